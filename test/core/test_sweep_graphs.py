"""Sweeps on communication graphs (core.sweep.graphs): a batch equals separate simulate runs."""

import numpy as np
import pytest
from scipy.sparse import csgraph

from polymatch_ros.core import simulate
from polymatch_ros.core.errors import ParameterError, SceneError
from polymatch_ros.core.sweep import scenes as sweep_scenes
from polymatch_ros.core.sweep.run import run_batch
from polymatch_ros.core.sweep.scenes import Cell, cell_scenes, graph_spec, template

DIRECTED = {"edges": [[0, 1], [1, 2], [2, 3], [3, 0], [0, 2]],
            "weights": [1.0, 2.0, 1.0, 1.5, 0.5], "directed": True}
CASES = [  # (cell, template graph): every graph kind, both orders, d = 2 .. 5
    (Cell(agents=5, graph="ring:1"), None),
    (Cell(agents=6, graph="k_nearest:3", order=2, mass=0.5), None),
    (Cell(dim=3, agents=6, graph="random:0.5", normalise="degree"), None),
    (Cell(dim=4, agents=4), DIRECTED),
    (Cell(dim=5, agents=5, graph="ring:1", order=2, mass=0.5, normalise="degree"), None),
]


def _scenes(cell, graph, ensembles=3):
    """``ensembles`` of the cell to t = 6, at dt = 0.25 (samples every 2 steps): the batch and
    the separate runs step alike; the same ensembles leave, at the same samples, as at 0.1."""
    data = template("congruent_triangles")
    data["time"] = {"t_end": 6.0, "samples": {"every": 0.5}}
    data["integrator"] = {"method": "rkmk4", "dt": 0.25}
    data["convergence"] = {"tolerance": 2.0}            # some ensembles leave the batch early
    if graph is not None:
        data["graph"] = graph
    return cell_scenes(data, cell, ensembles, seed=3)


@pytest.mark.parametrize("cell,graph", CASES,
                         ids=[f"d{c.dim or 2}-{c.graph or 'edges'}" for c, _ in CASES])
def test_batch_on_graphs_equals_separate_simulate_runs(cell, graph):
    """(A-1)/(A-2) with sum_k a_ik: B ensembles, each on its own graph, in one batch = B runs of
    the core's own graph model (``simulate``), to round-off, also after ensembles leave."""
    scenes = _scenes(cell, graph)
    result = run_batch(scenes)
    assert result.graph == scenes[0].model.groups[0].graph.kind
    for b, scene in enumerate(scenes):
        traj = simulate(scene, stop_when_converged=True)
        final = traj.final.groups[0]
        assert result.final_t[b] == traj.times[-1]
        np.testing.assert_allclose(result.final_x[b], final.x, rtol=0, atol=1e-11)
        np.testing.assert_allclose(result.final_rot[b],
                                   traj.scene.model.rotations.to_matrices(final.rot),
                                   rtol=0, atol=1e-11)
        np.testing.assert_allclose(result.diameters[:len(traj.times), b], traj.diameters,
                                   rtol=1e-9, atol=1e-11)
    left = ~np.isnan(result.converged_at)
    assert left.any() and (result.final_t[left] < result.final_t.max()).any(), result.final_t


def test_random_graphs_are_drawn_per_ensemble_and_connected():
    """random:P without a seed: each ensemble its own G(N, p), redrawn until connected (checked
    here by scipy's connected components); with a seed every ensemble shares one graph."""
    scenes = _scenes(Cell(agents=9, graph="random:0.3"), None, ensembles=6)
    mats = [s.model.groups[0].graph.matrix().toarray() for s in scenes]
    assert len({m.tobytes() for m in mats}) == 6
    for m in mats:
        assert np.array_equal(m, m.T) and set(np.unique(m)) <= {0.0, 1.0}
        assert csgraph.connected_components(m, directed=False)[0] == 1
    fixed = _scenes(Cell(agents=9), {"random": {"p": 0.5, "seed": 4}}, ensembles=3)
    assert len({s.model.groups[0].graph.matrix().toarray().tobytes() for s in fixed}) == 1


def test_graphs_a_batch_cannot_match_on_are_refused_naming_the_seed(monkeypatch):
    with pytest.raises(SceneError, match=r"^seed 3: graph \(groups\[0\]\): the graph is "
                       "disconnected"):
        _scenes(Cell(agents=10, graph="k_nearest:1"), None)
    # refused once every draw is disconnected: 20 draws here (the 1000 of GRAPH_DRAWS take long),
    # and the message counts them
    monkeypatch.setattr(sweep_scenes, "GRAPH_DRAWS", 20)
    with pytest.raises(ParameterError, match="random p = 0.01 gave no connected graph of 8 "
                                             "agents in 20 draws"):
        _scenes(Cell(graph="random:0.01"), None)
    with pytest.raises(SceneError, match=r"graph.random.p: must be <= 1, got 1.5"):
        _scenes(Cell(graph="random:1.5"), None)


def test_graph_spec_text():
    assert graph_spec("ring:2") == {"ring": 2}
    assert graph_spec("random:0.25") == {"random": {"p": 0.25}}
    assert graph_spec("complete") == "complete"
    for bad, words in (("star:3", "expected complete, ring:K"), ("ring:x", "an integer"),
                       ("random:", "expected complete")):
        with pytest.raises(ParameterError, match=words):
            graph_spec(bad)
