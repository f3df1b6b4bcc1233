"""Every agent's row to the model's State (``wire.state_of``), as the runner's final state, a
run's partial state and a recording's states take it: the State of a mixed scene (F-2, a
triangle group and a tetrahedron group) cut into rows and put back is the same
State, agent by agent and in agent-index order, whatever order the rows come in."""

import numpy as np
import pytest
from ros_harness import scene_path

from polymatch_ros.core.scenes.scene import load_scene
from polymatch_ros.ros import wire


def _rows(scene, state, order):
    """{agent: Row} cut out of ``state`` by hand (numpy indexing), in ``order``."""
    model = scene.model
    rows = {}
    for g, gs in zip(model.groups, state.groups):
        for r in range(g.size):
            rows[g.start + r] = wire.Row(gs.x[r].copy(), model.rotations.take(gs.rot, [r]))
    return {a: rows[a] for a in order}


@pytest.mark.parametrize("shuffled", [False, True])
def test_rows_put_back_are_the_state_they_were_cut_from(shuffled):
    scene = load_scene(scene_path("mixed_triangles_tetrahedra"))
    state = scene.initial
    order = list(range(scene.model.n_agents))
    if shuffled:
        order = list(np.random.default_rng(3).permutation(order))
    rows = _rows(scene, state, order)
    got = wire.state_of(scene.model, rows, 2.5)
    assert got.t == 2.5 and len(got.groups) == len(state.groups)
    grp = scene.model.rotations
    for g, a, b in zip(scene.model.groups, got.groups, state.groups):
        assert np.array_equal(a.x, b.x), g.name
        assert np.array_equal(grp.to_matrices(a.rot), grp.to_matrices(b.rot)), g.name
        assert a.v is None and a.w is None   # no velocities given: a first-order view


def test_a_missing_agent_is_an_error_not_a_silent_hole():
    scene = load_scene(scene_path("congruent_triangles"))
    rows = _rows(scene, scene.initial, range(scene.model.n_agents - 1))
    with pytest.raises(KeyError):
        wire.state_of(scene.model, rows, 0.0)
