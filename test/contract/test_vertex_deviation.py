"""The runner's "max vertex deviation" (``summary.vertex_deviation``), what the lockstep and
fault tests read from a run's summary, against brute force and closed forms."""

import math

import numpy as np
import pytest
from ros_harness import scene_path

from polymatch_ros.core.model import GroupState, State
from polymatch_ros.core.scenes.scene import load_scene
from polymatch_ros.ros.supervisor.summary import vertex_deviation


def _brute(model, a, b):
    """max over groups, agents i and reference vertices r of |(x_i + O_i r)(a) - (...)(b)|, one
    vertex at a time from the rotation matrices."""
    worst = 0.0
    for g, ga, gb in zip(model.groups, a.groups, b.groups):
        ma, mb = model.rotations.to_matrices(ga.rot), model.rotations.to_matrices(gb.rot)
        for i in range(len(ga.x)):
            for r in g.reference:
                gap = (ga.x[i] + ma[i] @ r) - (gb.x[i] + mb[i] @ r)
                worst = max(worst, math.sqrt(float(gap @ gap)))
    return worst


def _moved(model, state, rng):
    groups = []
    for gs in state.groups:
        n, d = gs.x.shape
        mats = np.linalg.qr(rng.normal(size=(n, d, d)))[0]
        mats[np.linalg.det(mats) < 0, :, 0] *= -1
        groups.append(GroupState(gs.x + rng.normal(size=(n, d)),
                                 model.rotations.from_matrices(mats)))
    return State(state.t, tuple(groups))


@pytest.mark.parametrize("name", ["congruent_triangles", "mixed_triangles_tetrahedra",
                                  "simplices_4d"])
def test_vertex_deviation_is_the_brute_force_maximum(name):
    scene = load_scene(scene_path(name))
    rng = np.random.default_rng(len(name))
    for _ in range(3):
        moved = _moved(scene.model, scene.initial, rng)
        assert vertex_deviation(scene.model, scene.initial, moved) == pytest.approx(
            _brute(scene.model, scene.initial, moved), rel=1e-12)
    assert vertex_deviation(scene.model, scene.initial, scene.initial) == 0.0


def test_vertex_deviation_of_one_shifted_and_one_turned_agent_closed_form():
    """Agent 2 shifted by (0.3, -0.4): 0.5.  Agent 5 turned by theta about its centroid: its
    farthest vertex moves 2 sin(theta/2) max|r|."""
    scene = load_scene(scene_path("congruent_triangles"))
    model, gs = scene.model, scene.initial.groups[0]
    x = gs.x.copy()
    x[2] += [0.3, -0.4]
    shifted = State(0.0, (GroupState(x, gs.rot),))
    assert vertex_deviation(model, scene.initial, shifted) == pytest.approx(0.5, rel=1e-12)
    theta = 0.7
    mats = model.rotations.to_matrices(gs.rot)
    turn = np.array([[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]])
    mats[5] = turn @ mats[5]
    turned = State(0.0, (GroupState(gs.x, model.rotations.from_matrices(mats)),))
    radius = float(np.linalg.norm(model.groups[0].reference, axis=1).max())
    assert vertex_deviation(model, scene.initial, turned) == pytest.approx(
        2 * math.sin(theta / 2) * radius, rel=1e-12)
