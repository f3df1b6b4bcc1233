"""The batched Cayley forms of core.so.cayley against the definition by LAPACK solves, and the
closed-form maps of SO(2) and SO(3) against scipy's matrix exponential."""

import math

import numpy as np
import pytest
from core_testlib import defect, rot_matrices, skew_matrices
from hypothesis import example, given, settings
from hypothesis import strategies as st
from scipy.linalg import expm

from polymatch_ros.core.so import SO3, SO4, SOn, base, group_for
from polymatch_ros.core.so.cayley import SERIES_LIMIT, cayley_series
from polymatch_ros.core.so.so4_quaternions import (
    cayley4,
    dcay_inv4,
    pair_matrices,
    quaternion_pairs,
)
from polymatch_ros.core.stepping.solver import lincomb


def _skew(rng, n, d, scale):
    w = rng.normal(size=(n, d, d)) * scale
    return w - np.swapaxes(w, 1, 2)


def _rotations(rng, n, d):
    q, r = np.linalg.qr(rng.normal(size=(n, d, d)))
    q *= np.sign(np.diagonal(r, axis1=1, axis2=2))[:, None, :]
    q[np.linalg.det(q) < 0, :, 0] *= -1.0
    return q


def _cayley_by_solve(w, g):
    eye = np.eye(w.shape[1])
    return np.linalg.solve(eye - 0.5 * w, (eye + 0.5 * w) @ g)


@pytest.mark.parametrize("scale", [1e-3, 0.1, 1.0, 30.0])
def test_so4_closed_form_cayley_and_inverse_differential_equal_the_definition(scale):
    rng = np.random.default_rng(4)
    w, a = _skew(rng, 300, 4, scale), _skew(rng, 300, 4, 1.0)
    eye = np.eye(4)
    cay = cayley4(w)
    np.testing.assert_allclose(cay, _cayley_by_solve(w, np.broadcast_to(eye, w.shape)),
                               rtol=0, atol=1e-14)
    assert np.max(np.abs(np.swapaxes(cay, 1, 2) @ cay - eye)) < 1e-14       # in SO(4) ...
    assert np.all(np.linalg.det(cay) > 0)                                   # ... not O(4)
    want = (eye - 0.5 * w) @ a @ (eye + 0.5 * w)
    np.testing.assert_allclose(dcay_inv4(w, a), want, rtol=0, atol=1e-13 * max(1.0, scale ** 2))


@pytest.mark.parametrize("dim", [3, 5, 10])
def test_cayley_series_equals_the_solve_inside_and_beyond_its_limit(dim):
    rng = np.random.default_rng(dim)
    # rows near zero, near the limit |W|_F^2 / 8 = SERIES_LIMIT, and far beyond it (LAPACK)
    w = np.concatenate([_skew(rng, 50, dim, 1e-3), _skew(rng, 50, dim, 1.0)])
    norms = np.sqrt(np.einsum("nij,nij->n", w, w))
    w[50:75] *= (np.sqrt(8 * SERIES_LIMIT) * 0.999 / norms[50:75])[:, None, None]
    g = _rotations(rng, len(w), dim)
    got = cayley_series(w, g)
    np.testing.assert_allclose(got, _cayley_by_solve(w, g), rtol=0, atol=1e-14)
    small = slice(0, 50)                          # a batch of small rows only: fewer factors
    np.testing.assert_allclose(cayley_series(w[small], g[small]), _cayley_by_solve(w, g)[small],
                               rtol=0, atol=1e-14)
    gram = np.swapaxes(got, 1, 2) @ got
    assert np.max(np.abs(gram - np.eye(dim))) < 1e-14


def test_cayley_series_rows_do_not_depend_on_the_rest_of_the_batch():
    """A lockstep agent retracts its own rows only; the centralised run retracts all of them."""
    rng = np.random.default_rng(7)
    w = np.concatenate([_skew(rng, 20, 6, 1e-2), _skew(rng, 20, 6, 2.0)])
    g = _rotations(rng, len(w), 6)
    batch = cayley_series(w, g)
    for i in (0, 5, 25, 39):
        np.testing.assert_allclose(cayley_series(w[i:i + 1], g[i:i + 1])[0], batch[i],
                                   rtol=0, atol=2e-15)


@pytest.mark.parametrize("dim", [3, 4, 7])
def test_son_maps_are_the_cayley_map_and_its_inverse_differential(dim):
    rng = np.random.default_rng(11)
    grp = SOn(dim)
    w, a = _skew(rng, 40, dim, 0.5), _skew(rng, 40, dim, 1.0)
    g = _rotations(rng, 40, dim)
    eye = np.eye(dim)
    np.testing.assert_allclose(grp.retract(w, g), _cayley_by_solve(w, g), rtol=0, atol=1e-14)
    np.testing.assert_allclose(grp.dpsi_inv(w, a), (eye - 0.5 * w) @ a @ (eye + 0.5 * w),
                               rtol=0, atol=1e-14)


def test_so4_rotations_are_unit_quaternion_pairs_and_retractions_stay_in_so4():
    rng = np.random.default_rng(5)
    g = _rotations(rng, 200, 4)
    p, q = quaternion_pairs(g)
    np.testing.assert_allclose(np.linalg.norm(p, axis=0), 1.0, rtol=0, atol=1e-15)
    np.testing.assert_allclose(pair_matrices(p, q), g, rtol=0, atol=1e-14)
    grp, rot = SOn(4), g
    for _ in range(200):                       # repeated retractions: no drift off SO(4)
        rot = grp.retract(_skew(rng, 200, 4, 0.3), rot)
    assert np.max(np.abs(np.swapaxes(rot, 1, 2) @ rot - np.eye(4))) < 1e-14
    assert np.all(np.linalg.det(rot) > 0)


def test_so4_self_dual_algebra_agrees_with_the_skew_matrix_representation():
    """SO4 (so(4) as (6, N) parts) and SOn(4) (skew matrices) are the same maps to round-off."""
    rng = np.random.default_rng(6)
    g, w, x = _rotations(rng, 100, 4), _skew(rng, 100, 4, 0.3), _skew(rng, 100, 4, 1.0)
    soa, mat = SO4(), SOn(4)
    xi, a = soa.algebra_from_skew(w), soa.algebra_from_skew(x)
    assert xi.shape == (6, 100)
    np.testing.assert_allclose(soa.algebra_to_skew(xi), w, rtol=0, atol=1e-15)
    np.testing.assert_allclose(soa.algebra_sq_norm(xi), mat.algebra_sq_norm(w), rtol=1e-14)
    np.testing.assert_allclose(soa.retract(xi, g), mat.retract(w, g), rtol=0, atol=1e-14)
    np.testing.assert_allclose(soa.algebra_to_skew(soa.dpsi_inv(xi, a)), mat.dpsi_inv(w, x),
                               rtol=0, atol=1e-14)
    s, fields = mat.mean_field(g), g[::-1].copy()          # one field, and one per row
    for field in (s, fields):
        np.testing.assert_allclose(soa.algebra_to_skew(soa.coupling(g, field)),
                                   mat.coupling(g, field), rtol=0, atol=1e-13)
    np.testing.assert_allclose(soa.tangent(xi, g), mat.tangent(w, g), rtol=0, atol=1e-15)
    assert group_for(4).__class__ is SO4 and group_for(4, "matrix").__class__ is SO4


def test_so4_steps_hand_on_their_quaternion_pairs_without_drifting_off_so4():
    """Each retraction's pair is the next base's pair (renormalised): no round-off build-up."""
    rng = np.random.default_rng(7)
    grp, rot = SO4(), _rotations(rng, 200, 4)
    for _ in range(300):
        rot = grp.retract(grp.algebra_from_skew(_skew(rng, 200, 4, 0.3)), rot)
    assert np.max(np.abs(np.swapaxes(rot, 1, 2) @ rot - np.eye(4))) < 1e-14
    p, q = grp._quaternion_pairs(rot)
    np.testing.assert_allclose(pair_matrices(p, q), rot, rtol=0, atol=1e-14)


def test_recycled_arrays_are_handed_out_again_only_once_nothing_refers_to_them():
    shape = (base.RECYCLED_MIN_BYTES // 8 + 1,)
    first, second = base.recycled(shape), base.recycled(shape)
    assert not np.shares_memory(first, second)          # both held: two arrays
    view = first[::2]
    del first                                            # a view still refers to it
    third = base.recycled(shape)
    assert not np.shares_memory(third, view) and not np.shares_memory(third, second)
    address = third.__array_interface__["data"][0]
    del third                                            # nothing refers to it any more
    assert base.recycled(shape).__array_interface__["data"][0] == address


def test_row_blocks_leave_every_bit_of_the_batched_forms_unchanged(monkeypatch):
    """Cayley retraction, dcay^{-1}, the Lohe kernel and stage sums, whole and in blocks."""
    rng = np.random.default_rng(12)
    grp = SOn(6)
    # 500 rows: arrays above RECYCLED_MIN_BYTES, which smaller ones skip the blocks below
    n = 500
    assert n * 6 * 6 * 8 >= base.RECYCLED_MIN_BYTES
    w, a, g = _skew(rng, n, 6, 1e-2), _skew(rng, n, 6, 1.0), _rotations(rng, n, 6)
    s = grp.mean_field(g)

    def forms():
        return [grp.retract(w, g).copy(), grp.dpsi_inv(w, a).copy(),
                grp.coupling(g, s).copy(), lincomb(g, 0.1, [0.5, 0.0, 0.25], [w, a, a]).copy()]

    whole = forms()
    monkeypatch.setattr(base, "ROW_BLOCK_BYTES", 7 * 6 * 6 * 8)          # blocks of 7 rows
    assert base.row_blocks(g.shape)[0] == 7
    for got, want in zip(forms(), whole):
        assert np.array_equal(got, want)


# ---------------------------------------------------------------------------------------------
# the closed-form maps of SO(2) and SO(3) against scipy's matrix exponential and the solve

#: rotation angles from exactly 0 through the series' thresholds, pi and beyond
SPECIAL_ANGLES = [0.0, 1e-12, 1e-8, 1e-4, 1e-3, np.pi - 1e-9, np.pi, np.pi + 1e-9, 2 * np.pi]
ANGLES = st.one_of(st.sampled_from(SPECIAL_ANGLES), st.floats(0.0, 1e-3),
                   st.floats(0.0, 4 * np.pi))
AXES = st.tuples(*[st.floats(-1.0, 1.0)] * 3).filter(lambda v: np.linalg.norm(v) > 1e-3)
# 30 drawn examples (up to 8 angles each, cheap: mostly spent drawing them), after the literal
# bands below as explicit examples: 95 angles, every special one of ANGLES on every axis, in
# three vectorised calls per test (100 drawn examples alone covered ~450 random angles)
CLOSED_FORMS = settings(max_examples=30, deadline=None)

#: literal axes: the coordinate axes both ways, diagonals, a generic one, and a short one
#: (|v| = 1.2e-3, next to AXES' filter 1e-3: normalising it is what is exercised)
BAND_AXES = [(1.0, 0.0, 0.0), (0.0, -1.0, 0.0), (0.0, 0.0, 1.0), (1.0, 1.0, 0.0),
             (-1.0, 1.0, -1.0), (0.3, -0.8, 0.5), (-0.61, 0.07, 0.93), (1e-3, -6e-4, 2e-4)]
#: angle bands, each checked to its own round-off (_round_off of its largest angle): [0, 1e-3]
#: (the series' side of every threshold), (1e-3, 2 pi] through pi, and (2 pi, 4 pi]; each holds
#: the special angles in its range
ANGLE_BANDS = [
    [float(t) for t in sorted(set(SPECIAL_ANGLES[:5]) | set(np.logspace(-16, -3, 27)))],
    [float(t) for t in sorted(set(SPECIAL_ANGLES[5:]) | set(np.linspace(0, 2 * np.pi, 34)[1:])
                              | {np.pi / 2, np.pi - 1e-6, np.pi + 1e-6, 2 * np.pi - 1e-9})],
    [float(t) for t in sorted(set(np.linspace(2 * np.pi, 4 * np.pi, 26)[1:])
                              | {3 * np.pi, 4 * np.pi - 1e-9})],
]


def _band_cases(band, every_axis):
    """A band's (axis, angle) pairs: every angle on every axis of BAND_AXES; or, for an oracle
    that pays per matrix (scipy's expm: a LAPACK getrs each, slow with multi-threaded
    OpenBLAS on a busy machine), the special angles on every axis and the others on one each,
    the axes in turn."""
    pairs = []
    for k, t in enumerate(band):
        axes = BAND_AXES if every_axis or t in SPECIAL_ANGLES else [BAND_AXES[k % len(BAND_AXES)]]
        pairs += [(axis, t) for axis in axes]
    return pairs


def _so3_bands(*extra, every_axis=True):
    """Every band of ANGLE_BANDS (_band_cases) as an explicit example (cases, *extra) of an
    SO(3) test; ``extra(n)`` gives its other arguments for n cases."""
    def decorate(test):
        for band in ANGLE_BANDS:
            cases = _band_cases(band, every_axis)
            test = example(cases, *[make(len(cases)) for make in extra])(test)
        return test
    return decorate


def _seed(n):
    """The seed of the band's random rotations O (its size: one per band)."""
    return n


def _slopes(n):
    """n slope axes for the inverse differentials, cycling through BAND_AXES."""
    return [BAND_AXES[(3 * k + 1) % len(BAND_AXES)] for k in range(n)]


def _round_off(angles):
    """What two evaluations of a map at angle t may differ by: eps-sized terms of size t^2."""
    return 4e-15 * (1.0 + np.max(np.abs(angles))) ** 2


def _expm_batch(skews):
    return expm(skews)                           # scipy's expm of every matrix of the stack


def _so3_skews(axes, angles):
    w = np.array(axes, dtype=float).T
    w *= np.asarray(angles) / np.linalg.norm(w, axis=0)
    return w, skew_matrices(SO3(), w)


@CLOSED_FORMS
@_so3_bands(_seed, every_axis=False)
@given(st.lists(st.tuples(AXES, ANGLES), min_size=1, max_size=8), st.integers(0, 2 ** 31))
def test_so3_rodrigues_retraction_equals_scipy_expm_at_every_angle(cases, seed):
    """exp(W) O in closed form (Rodrigues, series near 0) is scipy's expm(W) O to round-off,
    near 0 and pi included, and stays in SO(3) (Lemma 2.1)."""
    grp = SO3("exp")
    w, skews = _so3_skews([a for a, _ in cases], [t for _, t in cases])
    o = _rotations(np.random.default_rng(seed), len(cases), 3)
    got = rot_matrices(grp, grp.retract(w, grp.from_matrices(o)))
    tol = _round_off([t for _, t in cases])
    np.testing.assert_allclose(got, _expm_batch(skews) @ o, rtol=0, atol=tol)
    assert defect(got) <= tol


@CLOSED_FORMS
@_so3_bands(_seed)
@given(st.lists(st.tuples(AXES, ANGLES), min_size=1, max_size=8), st.integers(0, 2 ** 31))
def test_so3_cayley_retraction_equals_the_solve_at_every_angle(cases, seed):
    """cay(W) O in closed form is (I - W/2)^{-1} (I + W/2) O, and stays in SO(3) (Lemma 2.1)."""
    grp = SO3("cayley")
    w, skews = _so3_skews([a for a, _ in cases], [t for _, t in cases])
    o = _rotations(np.random.default_rng(seed), len(cases), 3)
    got = rot_matrices(grp, grp.retract(w, grp.from_matrices(o)))
    tol = _round_off([t for _, t in cases])
    np.testing.assert_allclose(got, _cayley_by_solve(skews, o), rtol=0, atol=tol)
    assert defect(got) <= tol


@CLOSED_FORMS
@_so3_bands(_slopes)
@given(st.lists(st.tuples(AXES, ANGLES), min_size=1, max_size=8), st.lists(AXES, min_size=8,
                                                                            max_size=8))
def test_so3_inverse_differentials_equal_their_definitions(cases, slopes):
    """dexp^{-1}_W(A) = sum_k B_k/k! ad_W^k(A) (Bernoulli numbers, summed to round-off for
    |w| <= 1) and dcay^{-1}_W(A) = (I - W/2) A (I + W/2), at the same angles as above."""
    w, skews = _so3_skews([a for a, _ in cases], [t for _, t in cases])
    a = np.array(slopes[:len(cases)], dtype=float).T
    hat_a = skew_matrices(SO3(), a)
    eye = np.eye(3)
    cay = skew_matrices(SO3(), SO3("cayley").dpsi_inv(w, a))
    np.testing.assert_allclose(cay, (eye - 0.5 * skews) @ hat_a @ (eye + 0.5 * skews),
                               rtol=0, atol=_round_off([t for _, t in cases]))
    small = np.linalg.norm(w, axis=0) <= 1.0
    if np.any(small):
        got = skew_matrices(SO3(), SO3("exp").dpsi_inv(w[:, small], a[:, small]))
        np.testing.assert_allclose(got, _dexp_inv_series(skews[small], hat_a[small]),
                                   rtol=0, atol=1e-14)


def _dexp_inv_series(w, a, terms=40):
    """sum_k B_k / k! ad_W^k(A) with Bernoulli numbers B_k (B_1 = -1/2), for |W| <= 1."""
    from scipy.special import bernoulli
    b = bernoulli(terms)
    b[1] = -0.5
    out, term = np.zeros_like(a), a.copy()
    for k in range(terms):
        out += b[k] / math.factorial(k) * term
        term = w @ term - term @ w
    return out


def _so2_bands(test):
    """Every band of ANGLE_BANDS as an explicit example: the special angles with both signs,
    the others with the signs in turn (scipy's expm pays per matrix: _band_cases)."""
    for k, band in enumerate(ANGLE_BANDS):
        signed = [(t, s) for j, t in enumerate(band)
                  for s in ((True, False) if t in SPECIAL_ANGLES else (j % 2 == 0,))]
        angles, signs = [t for t, _ in signed], [s for _, s in signed]
        test = example(angles, signs, k)(test)
    return test


@CLOSED_FORMS
@_so2_bands
@given(st.lists(ANGLES, min_size=1, max_size=8), st.lists(st.booleans(), min_size=8,
                                                          max_size=8), st.integers(0, 2 ** 31))
def test_so2_matrix_retraction_equals_scipy_expm_at_every_angle(angles, signs, seed):
    """SOn(2)'s closed form cos(t) O + sin(t) J O is expm(t J) O, and stays in SO(2)."""
    t = np.array(angles) * np.where(signs[:len(angles)], 1.0, -1.0)
    skews = t[:, None, None] * np.array([[0.0, -1.0], [1.0, 0.0]])
    o = _rotations(np.random.default_rng(seed), len(t), 2)
    got = SOn(2).retract(skews, o)
    np.testing.assert_allclose(got, _expm_batch(skews) @ o, rtol=0, atol=_round_off(t))
    assert defect(got) <= 4e-15
