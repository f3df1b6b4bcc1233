"""Section 3 decomposition x^i_a = xbar^i + s^i O^i r_a (Lemma 3.2) and its one-line errors."""

import warnings

import numpy as np
import pytest
from scipy.optimize import minimize_scalar
from scipy.spatial.transform import Rotation
from scipy.stats import special_ortho_group

from polymatch_ros.core import SceneError, ShapeError, decompose
from polymatch_ros.core.scenes.decompose import RotationNotUniqueWarning
from polymatch_ros.core.scenes.shapes import hypercube, polygon, simplex

SHAPES = {2: [polygon(5), hypercube(2)], 3: [simplex(3), hypercube(3)],
          4: [simplex(4), hypercube(4)]}


def _random_rotations(dim, count, rng):
    if dim == 3:
        return Rotation.random(count, random_state=rng).as_matrix()
    return special_ortho_group.rvs(dim, size=count, random_state=rng).reshape(count, dim, dim)


def _place(reference, centroids, rotations, scales):
    """x^i_a = xbar^i + s^i O^i r_a, written out per polytope."""
    return np.array([c + s * reference @ o.T for c, o, s in zip(centroids, rotations, scales)])


@pytest.mark.parametrize("similar", [False, True])
@pytest.mark.parametrize("dim", [2, 3, 4])
def test_decompose_recovers_rigid_motion_lemma_3_2_and_similarity_F_1(dim, similar):
    rng = np.random.default_rng(100 + dim)
    n = 8
    for shape in SHAPES[dim]:
        ref = shape.vertices
        assert np.allclose(ref.mean(axis=0), 0.0)
        rots = _random_rotations(dim, n, rng)
        cents = rng.normal(scale=10.0, size=(n, dim))
        scales = np.exp(rng.uniform(np.log(0.1), np.log(10.0), n)) if similar else np.ones(n)
        verts = _place(ref, cents, rots, scales)
        c, o, s = decompose(verts, ref, similar=similar)
        np.testing.assert_allclose(o, rots, rtol=0, atol=1e-12)
        np.testing.assert_allclose(c, cents, rtol=1e-14, atol=1e-12)
        np.testing.assert_allclose(s, scales, rtol=1e-12, atol=0)
        np.testing.assert_allclose(np.linalg.det(o), 1.0, atol=1e-12)


def test_decompose_rejects_scaled_copy_unless_similar_F_1():
    ref = polygon(3).vertices
    with pytest.raises(ShapeError, match="not congruent"):
        decompose([ref * 1.5], ref)
    _, _, s = decompose([ref * 1.5], ref, similar=True)
    assert s[0] == pytest.approx(1.5, rel=1e-14)


def _bad_inputs():
    tri = polygon(3).vertices
    tet = simplex(3).vertices
    mirror = tri * np.array([1.0, -1.0])
    coincident = tri.copy()
    coincident[2] = coincident[0]
    nan = tri.copy()
    nan[1, 0] = np.nan
    inf = tet.copy()
    inf[3, 2] = -np.inf
    return [
        ("mirror", tri, [tri + 1.0, mirror + 2.0], ShapeError, ["polytope 1", "mirror"]),
        ("mirror-3d", tet, [tet * np.array([1.0, 1.0, -1.0])],
         ShapeError, ["polytope 0", "mirror"]),
        ("not-congruent", tri, [tri, tri * np.array([1.0, 1.3])],
         ShapeError, ["polytope 1", "not congruent"]),
        ("not-similar", tri, [tri * np.array([1.0, 1.3])], ShapeError, ["not similar"]),
        ("too-few-vertices", tri, [tri[:2]], ShapeError, ["polytope 0", "2 vertices", "3"]),
        ("coincident", tri, [coincident], SceneError, ["polytope 0", "coincide"]),
        ("nan", tri, [nan], ShapeError, ["polytope 0", "non-finite"]),
        ("inf", tet, [tet, inf], ShapeError, ["polytope 1", "non-finite"]),
        ("wrong-dimension", tri, [np.hstack([tri, np.zeros((3, 1))])],
         ShapeError, ["3 coordinates", "dimension 2"]),
    ]


@pytest.mark.parametrize("case", _bad_inputs(), ids=lambda c: c[0])
def test_decompose_bad_input_one_line_error_lemma_3_2(case):
    name, ref, sets, exc_type, fragments = case
    with pytest.raises(exc_type) as exc:
        decompose(sets, ref, similar=(name == "not-similar"))
    msg = str(exc.value)
    assert "\n" not in msg and msg.strip() == msg and len(msg) < 300
    for frag in fragments:
        assert frag in msg, (frag, msg)


def test_decompose_coincident_vertices_raise_shape_error_lemma_3_2():
    tri = polygon(3).vertices.copy()
    tri[2] = tri[0]
    with pytest.raises(ShapeError):
        decompose([tri], polygon(3).vertices)


# ---------------------------------------------------------------------------------------------
# Lemma 3.2 fails for k <= d - 2: rotation not unique, least-angle choice


def _rodrigues_align(a, b):
    """The minimal rotation taking unit vector a to unit vector b (about a x b)."""
    v = np.cross(a, b)
    c = float(a @ b)
    k = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + k + k @ k / (1.0 + c)


def test_rotation_not_unique_least_angle_segment_in_r3_lemma_3_2():
    ref = np.array([[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    rng = np.random.default_rng(7)
    dirs = rng.normal(size=(6, 3))
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    cents = rng.normal(size=(6, 3))
    sets = [c + np.outer([-1.0, 1.0], u) for c, u in zip(cents, dirs)]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        c, o, s = decompose(sets, ref)
    ours = [w for w in caught if issubclass(w.category, RotationNotUniqueWarning)]
    assert len(ours) == 1 and "\n" not in str(ours[0].message)
    np.testing.assert_allclose(c, cents, atol=1e-13)
    for oi, u in zip(o, dirs):
        np.testing.assert_allclose(oi.T @ oi, np.eye(3), atol=1e-13)
        assert np.linalg.det(oi) == pytest.approx(1.0, abs=1e-13)
        np.testing.assert_allclose(oi @ [1.0, 0.0, 0.0], u, atol=1e-13)   # fits the vertices
        # least angle: the minimal rotation e1 -> u, trace 1 + 2 cos(angle(e1, u))
        np.testing.assert_allclose(oi, _rodrigues_align(np.array([1.0, 0.0, 0.0]), u), atol=1e-12)
        assert np.trace(oi) == pytest.approx(1.0 + 2.0 * u[0], abs=1e-12)
        # and no member of the fitting family O R_e1(phi) has a larger trace
        for phi in np.linspace(-np.pi, np.pi, 721):
            rx = np.array([[1, 0, 0], [0, np.cos(phi), -np.sin(phi)],
                          [0, np.sin(phi), np.cos(phi)]])
            assert np.trace(oi @ rx) <= np.trace(oi) + 1e-12


def test_rotation_not_unique_least_angle_triangle_in_r4_lemma_3_2():
    tri = np.hstack([polygon(3).vertices, np.zeros((3, 2))])         # spans 2 of 4 dimensions
    rng = np.random.default_rng(8)
    rots = special_ortho_group.rvs(4, size=4, random_state=rng)
    sets = [tri @ r.T for r in rots]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        _, o, _ = decompose(sets, tri)
    assert sum(issubclass(w.category, RotationNotUniqueWarning) for w in caught) == 1
    for oi, verts in zip(o, sets):
        np.testing.assert_allclose(tri @ oi.T, verts, atol=1e-12)
        assert np.linalg.det(oi) == pytest.approx(1.0, abs=1e-12)

        # the fitting rotations are oi @ diag(I_2, R(phi)); none may have a larger trace
        def neg_trace(phi, oi=oi):
            r = np.eye(4)
            r[2:, 2:] = [[np.cos(phi), -np.sin(phi)], [np.sin(phi), np.cos(phi)]]
            return -np.trace(oi @ r)
        grid = min(neg_trace(p) for p in np.linspace(-np.pi, np.pi, 721))
        best = minimize_scalar(neg_trace, bounds=(-np.pi, np.pi), method="bounded",
                               options={"xatol": 1e-12}).fun
        assert -neg_trace(0.0) >= -min(grid, best) - 1e-9


def test_no_warning_for_full_or_hyperplane_rank_lemma_3_2():
    tri3 = np.hstack([polygon(3).vertices, np.zeros((3, 1))])        # k = d - 1: still unique
    rot = Rotation.from_rotvec([0.3, -0.2, 1.1]).as_matrix()
    with warnings.catch_warnings():
        warnings.simplefilter("error", RotationNotUniqueWarning)
        _, o, _ = decompose([tri3 @ rot.T], tri3)
    np.testing.assert_allclose(o[0], rot, atol=1e-12)
