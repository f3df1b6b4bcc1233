"""Twisted states on rings (core.sweep.rings): winding numbers, loop classes, and which twists
unwind through the extra dimensions of SO(d), d >= 3 (pi_1(SO(d)) = Z2)."""

import numpy as np
import pytest
from scipy.linalg import expm, logm
from scipy.spatial.transform import Rotation

from polymatch_ros.core.sweep.rings import (
    perturbed,
    principal_logs,
    ring_measures,
    twisted_rotations,
)
from polymatch_ros.core.sweep.run import run_batch
from polymatch_ros.core.sweep.scenes import Cell, cell_scenes, template, with_rotations


def _quaternion_classes(loops):
    """+1 / -1 per loop (B, N, 3, 3): O_0 -> ... -> O_{N-1} -> O_0 lifted to unit quaternions
    (scipy), each step along the shorter arc (q_j . q_{j+1} > 0); -1 when it comes back as -q_0.
    The steps go one after another, every loop at once."""
    loops = np.asarray(loops)
    quats = Rotation.from_matrix(loops.reshape(-1, 3, 3)).as_quat().reshape(*loops.shape[:2], 4)
    lifted = quats[:, 0]
    for j in list(range(1, quats.shape[1])) + [0]:
        q = quats[:, j]
        lifted = np.where(np.einsum("bk,bk->b", lifted, q)[:, None] > 0, q, -q)
    return np.sign(np.einsum("bk,bk->b", lifted, quats[:, 0]))


def _quaternion_class(mats):
    """The class of one loop (N, 3, 3), as _quaternion_classes."""
    return float(_quaternion_classes(np.asarray(mats)[None])[0])


def _random_skew(rng, d, size):
    g = rng.standard_normal((d, d))
    a = g - g.T
    return size * a / np.linalg.norm(a, 2)


def test_winding_number_of_planar_phases():
    """d = 2: q = sum_j wrap(theta_{j+1} - theta_j) / 2 pi, from the phases themselves."""
    rng = np.random.default_rng(5)
    theta = rng.uniform(-np.pi, np.pi, (200, 9))
    mats = np.stack([np.stack([np.cos(theta), -np.sin(theta)], -1),
                     np.stack([np.sin(theta), np.cos(theta)], -1)], -2)
    steps = np.angle(np.exp(1j * (np.roll(theta, -1, axis=1) - theta)))
    q = np.rint(steps.sum(axis=1) / (2 * np.pi))
    got = ring_measures(mats)
    np.testing.assert_array_equal(got.winding, q)
    assert set(np.unique(q)) >= {-1.0, 0.0, 1.0}
    np.testing.assert_allclose(got.turn, np.abs(steps).sum(axis=1) / (2 * np.pi), atol=1e-12)
    np.testing.assert_array_equal(got.loop_class, (-1.0) ** q)     # the spin lift in SO(2)


def test_loop_class_in_so3_is_the_quaternion_lift():
    """Random loops in SO(3) (steps below a half-turn): the Clifford lift's sign = scipy's
    quaternions carried around the loop; both classes occur."""
    rng = np.random.default_rng(1)     # one draw of 300 x 5: the same as 300 draws of 5
    loops = Rotation.random(300 * 5, random_state=rng).as_matrix().reshape(300, 5, 3, 3)
    got = ring_measures(loops)
    assert np.all(got.step_max < np.pi - 1e-6)
    expected = _quaternion_classes(loops)
    np.testing.assert_array_equal(got.loop_class, expected)
    assert 50 < np.sum(expected < 0) < 250
    # the same loops inside SO(4) and SO(5) (a 3-d block): the class does not change
    for d in (4, 5):
        big = np.repeat(np.eye(d)[None, None], len(loops), axis=0).repeat(5, axis=1)
        big[:, :, :3, :3] = loops
        np.testing.assert_array_equal(ring_measures(big).loop_class, expected)


@pytest.mark.parametrize("d", [2, 3, 4, 5])
def test_planar_twists_turn_q_times_with_class_minus_one_to_the_q(d):
    """A q-twist in one plane, seen in any frame and slightly perturbed: total turn q (in full
    turns, from eigen-angles here), loop class (-1)^q: a 2 pi turn generates pi_1(SO(d))."""
    rng = np.random.default_rng(d)
    for q in (0, 1, 2, 3):
        base = rng.standard_normal((d, d))
        frame = expm(base - base.T)
        mats = frame @ perturbed(twisted_rotations(d, 16, q), 1e-3, rng) @ frame.T
        got = ring_measures(mats[None])
        steps = np.swapaxes(mats, -1, -2) @ np.roll(mats, -1, axis=0)
        angles = np.abs(np.angle(np.linalg.eigvals(steps))).max(axis=1)
        assert got.turn[0] == pytest.approx(angles.sum() / (2 * np.pi), abs=2e-3)
        assert round(float(got.turn[0])) == q
        assert got.loop_class[0] == (-1) ** q


def test_principal_logs_are_scipy_logm():
    rng = np.random.default_rng(3)
    for d in (2, 3, 4, 5):
        a = np.array([_random_skew(rng, d, rng.uniform(0, 3.0)) for _ in range(6)])
        rotations = expm(a)                          # scipy's expm of each, once
        logs, largest = principal_logs(rotations)
        for rot, got in zip(rotations, logs):
            np.testing.assert_allclose(got, logm(rot).real, atol=1e-9)
        np.testing.assert_allclose(largest, np.linalg.norm(a, 2, axis=(1, 2)), atol=1e-9)


def _ring_scenes(d, n, mats):
    """First order on a ring of n (k = 1, kappa/deg_i), centroids together, given rotations.
    dt = 1 (the ring's rates are at most 2: h lambda <= 2 < 2.78, rkmk4's limit): every run
    leaves at the sample and with the outcome it has at dt = 0.5, at |W| < 2e-6."""
    data = template("congruent_triangles")
    data.update(time={"t_end": 600.0, "samples": {"every": 5.0}},
                graph={"ring": 1, "normalise": "degree"},
                integrator={"method": "rkmk4", "dt": 1.0})
    data["groups"][0]["centroids"] = {"box": [0.0, 0.0]}
    scenes = cell_scenes(data, Cell(dim=d, agents=n), len(mats), seed=0)
    return [with_rotations(s, m) for s, m in zip(scenes, mats)]


def _ring_field(mats):
    """max_i |W_i|_F of (A-2) on the ring (k = 1, degree weights), written out here."""
    nb = np.roll(mats, -1, axis=0) + np.roll(mats, 1, axis=0)
    s = np.einsum("nij,nkj->nik", nb, mats)                     # (O_{i+1} + O_{i-1}) O_i^T
    return float(np.linalg.norm((s - np.swapaxes(s, 1, 2)) / 4.0, axis=(1, 2)).max())


def _diameters(mats, reference):
    """(rotation, vertex) diameters max |O_i - O_j|_F and max |O_i r_a - O_j r_a| (centroids
    together), by brute force over the pairs."""
    flat = mats.reshape(len(mats), -1)
    rot = np.linalg.norm(flat[:, None] - flat[None], axis=-1).max()
    verts = np.einsum("nij,aj->nai", mats, reference)
    return rot, np.linalg.norm(verts[:, None] - verts[None], axis=-1).max()


@pytest.mark.parametrize("d", [2, 3, 4])
def test_two_twist_unwinds_through_the_third_dimension_one_twist_stays(d):
    """Perturbed q-twists on a ring of 12 (eps = 0.05 rad in all of so(d), seeds 0, 1): in
    d = 2 both twists stay (winding q); in SO(3) and SO(4), whose loops have the classes Z2,
    the 2-twist (4 pi, contractible) unwinds to consensus and matches, the 1-twist (2 pi,
    not contractible) stays twisted.  Verified here: diameters by brute force, the field
    W_i written out, the loop class by quaternions (d = 3) and the turn by eigen-angles."""
    n, seeds, qs = 12, (0, 1), (1, 2)
    mats = np.array([perturbed(twisted_rotations(d, n, q), 0.05, np.random.default_rng((s, 7)))
                     for q in qs for s in seeds])
    scenes = _ring_scenes(d, n, mats)
    result = run_batch(scenes, settle=True)
    reference = scenes[0].model.groups[0].reference
    for (q, s), final, outcome in zip([(q, s) for q in qs for s in seeds], result.final_rot,
                                      result.outcome):
        rot, vert = _diameters(final, reference)
        assert _ring_field(final) < 1e-5, (d, q, s)             # an equilibrium either way
        if d >= 3 and q == 2:
            assert outcome == "matched" and vert < scenes[0].tolerance and rot < 1e-5, (q, s)
            continue
        assert outcome == "twisted" and rot > 1.0, (d, q, s, outcome)
        steps = np.swapaxes(final, -1, -2) @ np.roll(final, -1, axis=0)
        angles = np.abs(np.angle(np.linalg.eigvals(steps))).max(axis=1)
        np.testing.assert_allclose(angles, 2 * np.pi * q / n, atol=1e-4)   # uniform twist q
        if d == 3:
            assert _quaternion_class(final) == -1.0
    twisted = result.outcome == "twisted"
    assert list(np.rint(result.ring.turn[twisted])) == ([1, 1, 2, 2] if d == 2 else [1, 1])


def _ring_energy_hessian(mats):
    """Hessian of E = -sum_j tr(O_j^T O_{j+1}) (k = 1; (A-2) on the ring is its gradient flow,
    up to a constant) in body coordinates O_j exp(hat(x_j)), by central differences."""
    n, h = 3 * len(mats), 1e-4
    a, b = np.triu_indices(n)
    eye = np.eye(n) * h
    points = np.concatenate([eye[a] + eye[b], eye[a] - eye[b], eye[b] - eye[a],
                             -eye[a] - eye[b]])
    o = mats @ Rotation.from_rotvec(points.reshape(-1, 3)).as_matrix().reshape(
        len(points), len(mats), 3, 3)
    energy = -np.einsum("pnji,pnji->p", o, np.roll(o, -1, axis=1)).reshape(4, -1)
    hess = np.zeros((n, n))
    hess[a, b] = (energy[0] - energy[1] - energy[2] + energy[3]) / (4 * h * h)
    return np.linalg.eigvalsh(hess + np.triu(hess, 1).T)


def test_planar_twists_in_so3_are_saddles_except_the_one_twist():
    """Why the 2-twist unwinds: at a planar q-twist (step phi = 2 pi q / N) the rotations out
    of its plane, in the co-rotating wave of p = q/2 turns, lower the energy by
    2 cos(phi/2) (cos(phi/2) - 1) per site (the linearisation on the guide page), so even
    twists are saddles; odd q > 1 have the waves (q +- 1)/2, negative for q > 1 and zero for
    q = 1, whose only other flat directions are the 3 + 3 - 1 global rotations."""
    n = 16                                  # q <= 3 < N/4: every twist is stable in its plane
    for q, unstable in ((1, 0), (2, 2), (3, 4)):
        w = _ring_energy_hessian(twisted_rotations(3, n, q))
        assert np.sum(w < -1e-5) == unstable and np.sum(np.abs(w) < 1e-5) == 5, (q, w[:6])
        half = np.pi * q / n
        if q == 2:
            assert w[0] == pytest.approx(4 * np.cos(half) * (np.cos(half) - 1), rel=1e-5)
        if q == 3:
            expected = 4 * np.cos(half) * (np.cos(half) - np.cos(np.pi / n))
            assert w[0] == pytest.approx(expected, rel=1e-5)
