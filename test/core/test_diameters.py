"""Diameters in O(N log N) (core/diameters.py) and the certificate built on them at large N.

Thm 4.2's hypothesis D_O = max |O_i - O_j|_F < 1 and its bound D_x e^{-c t} + R/sqrt 2 D_O(t)
are decided and evaluated before a run; over EXACT_PAIRS_UP_TO agents the diameters are exact
where the convex hull (or, in 2-D, the phases' arc) gives them, else two-sided bounds.  The
oracle throughout is scipy's pdist over every pair (brute force, independent of the code).
"""

import math
import time

import numpy as np
import pytest
from core_testlib import make_scene, rot_matrices, vertices
from scipy.spatial.distance import pdist

from polymatch_ros import cli
from polymatch_ros.core.certificate import LoheBound, certify
from polymatch_ros.core.diameters import (
    EXACT_PAIRS_UP_TO,
    diameter,
    planar_rotation_diameter,
)

N = EXACT_PAIRS_UP_TO + 1000       # past the exact pairwise search: the large-N path


def brute(points):
    return float(pdist(np.asarray(points, dtype=float).reshape(len(points), -1)).max())


@pytest.mark.parametrize("k", [2, 3, 5, 9])
@pytest.mark.parametrize("cloud", ["box", "sphere", "cluster"])
def test_diameter_brackets_the_brute_force_farthest_pair(k, cloud):
    rng = np.random.default_rng(k)
    p = rng.uniform(-1.0, 1.0, (N, k))
    if cloud == "sphere":                      # every point on the hull: bounds, not the hull
        p /= np.linalg.norm(p, axis=1)[:, None]
    elif cloud == "cluster":
        p = 1e9 + 1e-3 * p                     # far from the origin, small spread
    got, want = diameter(p), brute(p)
    assert got.lower <= want * (1 + 1e-9) and want <= got.upper * (1 + 1e-9)
    assert got.upper <= 2.0 * got.lower * (1 + 1e-12)   # max |p - mean| <= D <= 2 max |p - mean|
    if k <= 3 and cloud == "box":              # few hull vertices: the exact farthest pair
        assert got.exact and got.upper == pytest.approx(want, rel=1e-9)


@pytest.mark.parametrize("arc", [0.1, 1.0, 3.0, 3.2, 6.0])
def test_planar_rotation_diameter_against_every_pair(arc):
    theta = np.random.default_rng(7).uniform(0.0, arc, N) + 5.0
    theta[:2] = 5.0, 5.0 + arc                 # the arc's ends are taken
    mats = np.stack([np.stack([np.cos(theta), -np.sin(theta)], -1),
                     np.stack([np.sin(theta), np.cos(theta)], -1)], -2)
    got, want = planar_rotation_diameter(theta), brute(mats)
    if arc < math.pi:                          # within an open half-circle: exact
        assert got.exact and got.upper == pytest.approx(want, rel=1e-9)
    else:
        assert got.lower <= want * (1 + 1e-12) and want <= got.upper * (1 + 1e-12)


@pytest.mark.parametrize("dim", [2, 3])
def test_certificate_at_large_n_bounds_the_brute_force_diameters_thm_4_2(dim):
    sc = make_scene(dim, count=N, seed=3, rotations={"within": 0.15}, t_end=10.0)
    cert = certify(sc.model, sc.initial, sc.tolerance)
    gs = sc.initial.groups[0]
    mats = rot_matrices(sc.model.rotations, gs.rot)
    assert cert.certified                      # brute force: D_O below 1, Thm 4.2 applies
    assert brute(mats) < 1.0
    bound = cert.bounds[0]
    assert isinstance(bound, LoheBound)
    assert bound.centroids >= brute(gs.x) * (1 - 1e-12)
    assert bound.rotations >= brute(mats) * (1 - 1e-12)
    verts = vertices(sc.model, sc.initial, 0)
    matching = max(brute(verts[:, a, :]) for a in range(verts.shape[1]))
    assert cert.bound(0.0) >= matching * (1 - 1e-12)
    if bound.bounded:                          # a value that is a bound is said to be one
        assert "upper bounds, not exact diameters" in cert.line()
        assert all(text.split(" <= ")[0] in cert.line() for text in bound.bounded)


def test_uniform_rotations_refused_from_a_lower_bound_thm_4_2():
    sc = make_scene(3, count=N, seed=4)        # Haar rotations: D_O ~ 2 sqrt 2
    cert = certify(sc.model, sc.initial, sc.tolerance)
    assert brute(rot_matrices(sc.model.rotations, sc.initial.groups[0].rot)) >= 1.0
    assert not cert.certified and ">= 1 (Thm 4.2" in cert.reason


def test_explain_of_a_large_scene_takes_linear_time(tmp_path, capsys):
    """200,000 agents: the exact pairwise diameters are quadratic; the checks are O(N log N)
    now, well within the bound below."""
    path = tmp_path / "large.yaml"
    path.write_text("dimension: 3\nmodel: {order: 1}\ntime: {t_end: 10}\n"
                    "groups:\n  - {shape: tetrahedron, count: 200000}\n")
    start = time.process_time()      # CPU seconds: a loaded machine stretches wall time
    assert cli.main(["explain", str(path)]) == 0
    assert time.process_time() - start < 10.0
    assert "not certified: D0 >= " in capsys.readouterr().out
