"""Lockstep over ROS on communication graphs: each agent hears only its in-neighbours.

On a graph the distributed run integrates the centroids with the stages (the exact
Laplacian flow reads every agent's centroid at each step), so it equals the centralised
`simulate` of the same scene with `model.centroids: integrated`, to round-off.  Every case
starts `polymatch run` in the test's own ROS domain and compares the saved final poses.
"""

import re

import numpy as np
import pytest
from exactness import central_vertices, received_vertices
from ros_harness import PY, needs_ros

from polymatch_ros.core.model import System
from polymatch_ros.core.scene import load_scene
from polymatch_ros.ros.nodes.exchange import Layout
from polymatch_ros.ros.wire import run_records

pytestmark = needs_ros

T_END = 1.0
SCENE = """\
name: graph_case
dimension: {dim}
seed: 4
model: {{order: {order}, kappa: 1.0, gamma: 1.0{mass}}}
graph: {graph}
integrator: {{method: {method}, dt: 0.05}}
time: {{t_end: 5.0}}
groups:
  - {{name: g, shape: {{simplex: {dim}}}, count: {count}, centroids: {{box: [-3.0, 3.0]}},
      rotations: uniform{velocities}}}
"""

CASES = [
    # graph, dimension, order, method, agents, agents per process
    ("{ring: 1}", 2, 1, "rkmk4", 8, 1),
    ("{k_nearest: 2}", 3, 2, "rkmk4", 7, 2),
    ("{random: {p: 0.4, seed: 3}}", 3, 1, "lie_euler", 6, 1),
    ("{ring: 2}", 2, 2, "rkmk4", 8, 3),
]


def write_scene(tmp_path, graph, dim, order, method, count):
    path = tmp_path / "graph_case.yaml"
    second = order == 2
    path.write_text(SCENE.format(
        dim=dim, order=order, graph=graph, method=method, count=count,
        mass=", mass: 0.5" if second else "",
        velocities=", velocities: {centroid: {normal: 0.5}}" if second else ""))
    return str(path)


def initial_vertices(scene):
    out = []
    for g, gs in zip(scene.model.groups, scene.initial.groups):
        mats = scene.model.rotations.to_matrices(gs.rot)
        out.append(gs.x + scene.origin
                   + np.einsum("nij,aj->nai", mats, g.reference).transpose(1, 0, 2))
    return out


def test_layout_on_a_ring_needs_the_in_neighbours_and_complete_scenes_everyone(tmp_path):
    ring = load_scene(write_scene(tmp_path, "{ring: 2}", 2, 1, "rkmk4", 8))
    model = ring.model
    assert model.centroids_exact        # the scene as written: exact centroids ...
    layout = Layout(model, [0])         # ... whose flow reads everyone at a step's start
    assert layout.sparse and layout.peers == list(range(1, 8))
    integrated = load_scene(write_scene(tmp_path, "{ring: 2}", 2, 1, "rkmk4", 8),
                            {"model.centroids": "integrated"}).model
    layout = Layout(integrated, [0, 1], agents_per_process=2)
    assert layout.peers == [2, 3, 6, 7]
    assert set(System(integrated).sources(0, 0, True)["x"]) == {1, 2, 6, 7}
    # processes of two: agent 2 is heard by 0, 1 (process 0), 3 (its own) and 4 (process 2);
    # agent 0 by 1 (its own), 2 (process 1), 6 and 7 (process 3)
    assert layout.expected_subscribers(2) == 2 and layout.expected_subscribers(0) == 2
    assert Layout(integrated, [4, 5], agents_per_process=2).expected_subscribers(5) == 2
    complete = load_scene(write_scene(tmp_path, "complete", 2, 1, "rkmk4", 8)).model
    layout = Layout(complete, [0, 1], agents_per_process=2)
    assert not layout.sparse and layout.peers == list(range(2, 8))
    assert layout.expected_subscribers(0) == 3
    # packed, the process's rows travel as block 0 to the three other processes ...
    assert layout.blocks and layout.local_blocks() == {0: [0, 1]}
    assert layout.peer_blocks() == [1, 2, 3] and layout.expected_block_subscribers(0) == 3
    # ... and on the ring of two, blocks 1 and 3 hold the in-neighbours 2, 3, 6 and 7
    ring_layout = Layout(integrated, [0, 1], agents_per_process=2)
    assert ring_layout.peer_blocks() == [1, 3] and ring_layout.expected_block_subscribers(0) == 2


@pytest.mark.parametrize("graph,dim,order,method,count,k", CASES)
def test_lockstep_on_a_graph_equals_the_centralised_run(ros, tmp_path, graph, dim, order,
                                                        method, count, k):
    path = write_scene(tmp_path, graph, dim, order, method, count)
    out, records = tmp_path / "final.npz", tmp_path / "records.jsonl"
    proc = ros.start([PY, "-m", "polymatch_ros.cli", "run", path, "--t-end", str(T_END),
                      "-k", str(k), "--timeout", "150", "--save", str(out),
                      "--records", str(records), "-q"], timeout=180)
    rc = ros.wait(proc, 190)
    text = ros.output(proc)
    assert rc in (0, 3), text
    scene = load_scene(path, {"model.centroids": "integrated"})
    t, got = received_vertices(scene, out)
    assert t == pytest.approx(T_END)
    want = central_vertices(scene, method, t)
    dev = max(float(np.max(np.linalg.norm(a - b, axis=-1))) for a, b in zip(got, want))
    assert dev <= 1e-9, f"max vertex deviation {dev:.3e}"
    m = re.search(r"max vertex deviation ([0-9.e+-]+)", text)   # the runner's comparison
    assert m and float(m.group(1)) <= 1e-9, text
    initial = initial_vertices(scene)                           # the agents did move
    assert max(float(np.max(np.linalg.norm(a - b, axis=-1))) for a, b in zip(got, initial)) > 0.05
    recs = [r for r in run_records(records.read_text().splitlines()) if r.role == "agent"]
    assert len(recs) == -(-count // k) and all(r.finished for r in recs), recs
    layout_model = scene.model
    for rec in recs:
        layout = Layout(layout_model, rec.agents, k)
        assert list(rec.peers) == layout.peers
        # one stage topic per peer, or packed (k > 1) one per block of k that holds a peer
        want = len(layout.peer_blocks()) if k > 1 else len(layout.peers)
        assert rec.stage_subscriptions == want
    if graph == "{ring: 1}":            # an agent on a ring of k = 1 subscribes to 2k stages
        assert all(rec.stage_subscriptions == 2 for rec in recs)
        assert sorted(recs[3].peers) == [2, 4]


STOP_SCENE = """\
name: graph_stop
dimension: 2
seed: 4
model: {order: 1, kappa: 8.0, gamma: 1.0}
graph: {ring: 1}
integrator: {method: rkmk4, dt: 0.1}
time: {t_end: 60.0}
convergence: {tolerance: 1.0e-3}
groups:
  - {name: g, shape: triangle, count: 6, centroids: {box: [-0.5, 0.5]}, rotations: {within: 0.2}}
"""


def test_a_stop_on_convergence_reaches_every_agent_of_a_ring_at_the_same_step(ros, tmp_path):
    """A stop spreads one hop per round on a graph; the agents agree on the step to stop at
    (nobody is left waiting for a neighbour that stopped) and the run still equals `simulate`."""
    path = tmp_path / "graph_stop.yaml"
    path.write_text(STOP_SCENE)
    records = tmp_path / "records.jsonl"
    # a process per agent (-k 1): the stop spreads between processes, one hop a round
    proc = ros.start([PY, "-m", "polymatch_ros.cli", "run", str(path), "--timeout", "150",
                      "--records", str(records), "-k", "1"], timeout=180)
    rc = ros.wait(proc, 190)
    text = ros.output(proc)
    assert rc == 0, text
    assert "converged: matching diameter < 0.001" in text
    m = re.search(r"max vertex deviation ([0-9.e+-]+)", text)
    assert m and float(m.group(1)) <= 1e-9, text
    agents = [r for r in run_records(records.read_text().splitlines()) if r.role == "agent"]
    assert len(agents) == 6 and all(r.finished for r in agents), agents
    assert len({r.steps for r in agents}) == 1 and agents[0].steps < 600   # stopped early
