"""Formations (core/robots/formation.py): consensus on x_i - c_i.

Prop. 2.1 under the change of variable y_i = x_i - c_i: first order, the centroids follow
x_i(t) = c_i + ybar + exp(-kappa t / gamma) (x_i(0) - c_i - ybar), written out here and
evaluated from the scene's initial centroids read without the formation.
Thm 4.2 (the certificate) on the formation coordinates: the certified bound holds for the
formation error computed from the world positions the test rebuilds.
"""

import math

import numpy as np
import pytest

from polymatch_ros.core import load_scene, simulate
from polymatch_ros.core.certificate import certify
from polymatch_ros.core.errors import SceneError
from polymatch_ros.core.robots.formation import positions

SCENE = {
    "name": "formation", "dimension": 2, "seed": 3,
    "model": {"order": 1, "kappa": 1.5, "gamma": 1.0},
    "integrator": {"method": "rkmk4", "dt": 0.05}, "time": {"t_end": 4.0},
    "groups": [{"name": "tri", "shape": "triangle", "count": 5,
                "centroids": {"box": [-4.0, 4.0]}, "rotations": {"within": 0.4}}],
}
OFFSETS = [[2.0, 0.0], [0.0, 2.0], [-2.0, 0.0], [0.0, -2.0], [0.5, 0.5]]


def _scene(**extra):
    return load_scene({**SCENE, **extra})


def _world(traj_scene, state):
    gs = state.groups[0]
    return positions(gs.x, traj_scene.formation, traj_scene.origin, slice(None))


def test_first_order_centroids_follow_the_closed_form_of_prop_2_1_in_formation_coordinates():
    plain = _scene()
    x0 = plain.initial.groups[0].x + plain.origin            # the world initial centroids
    c = np.array(OFFSETS)
    kappa, gamma = 1.5, 1.0
    ybar = (x0 - c).mean(axis=0)
    scene = _scene(formation={"offsets": OFFSETS})
    times = [0.0, 1.0, 2.5, 4.0]
    traj = simulate(scene, "rkmk4", 0.05, samples=times)
    for t, state in zip(traj.times, traj.states):
        expected = c + ybar + math.exp(-kappa * t / gamma) * (x0 - c - ybar)
        np.testing.assert_allclose(_world(scene, state), expected, rtol=0, atol=1e-12)


def test_second_order_formation_is_the_plain_model_on_shifted_centroids():
    """(A-1) on y = x - c: a scene whose centroids are x0 - c, run without formation, gives the
    formation's trajectory shifted by -c (the change of variable, second order)."""
    x0 = np.array([[3.0, -1.0], [0.5, 2.0], [-2.0, -3.0], [1.0, 4.0], [-3.5, 0.5]])
    c = np.array(OFFSETS)

    def second(points, **extra):
        groups = [dict(SCENE["groups"][0], centroids={"points": points.tolist()})]
        return _scene(model={"order": 2, "kappa": 1.0, "gamma": 1.5, "mass": 1.0},
                      groups=groups, **extra)
    scene, plain = second(x0, formation={"offsets": OFFSETS}), second(x0 - c)
    a = simulate(scene, "rkmk4", 0.05, samples=[0.0, 4.0]).final
    b = simulate(plain, "rkmk4", 0.05, samples=[0.0, 4.0]).final
    np.testing.assert_allclose(_world(scene, a) - c, b.groups[0].x + plain.origin, atol=1e-12)
    np.testing.assert_allclose(a.groups[0].v, b.groups[0].v, atol=1e-12)


def test_certificate_bounds_the_formation_error_measured_in_world_positions():
    scene = _scene(formation={"offsets": OFFSETS})
    cert = certify(scene.model, scene.initial, 1e-3)
    assert cert.certified, cert.line()
    times = np.linspace(0.0, 4.0, 9)
    traj = simulate(scene, "rkmk4", 0.01, samples=times)
    c = np.array(OFFSETS)
    ref = scene.model.groups[0].reference
    for t, state in zip(traj.times, traj.states):
        world = _world(scene, state)
        mats = scene.model.rotations.to_matrices(state.groups[0].rot)
        # formation error of the vertices: x_i - c_i + O_i r_a, compared pairwise (brute force)
        verts = (world - c)[:, None, :] + np.einsum("nij,aj->nai", mats, ref)
        err = max(np.linalg.norm(verts[i] - verts[j], axis=1).max()
                  for i in range(len(c)) for j in range(len(c)))
        assert err <= float(cert.bound(t)) * (1 + 1e-6) + 1e-12


def test_offsets_closer_than_twice_the_safety_radius_are_refused_in_one_line():
    with pytest.raises(SceneError, match=r"^formation: agents 0 and 4 are 1\.58 apart") as exc:
        _scene(formation={"offsets": OFFSETS}, safety={"radius": 1.0})
    assert "\n" not in str(exc.value)
    _scene(formation={"offsets": OFFSETS}, safety={"radius": 0.5})   # 2 r = 1 < 1.58: kept


@pytest.mark.parametrize("formation, message", [
    ({"offsets": [[0.0, 0.0]]}, r"^formation\.offsets: expected 5 rows of 2 numbers"),
    ({"circle": -1.0}, r"^formation\.circle: "),
    ({"groups": {"nope": [1.0, 0.0]}}, r"^formation\.groups\.nope: no such group"),
    ({}, r"^formation: give offsets"),
])
def test_bad_formations_are_refused_with_their_key_path(formation, message):
    with pytest.raises(SceneError, match=message):
        _scene(formation=formation)
