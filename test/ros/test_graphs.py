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

from polymatch_ros.core.scenes.scene import load_scene
from polymatch_ros.ros.wire import run_records
from polymatch_ros.ros.wire.intake import Layout

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


@pytest.mark.parametrize("graph,dim,order,method,count,k", CASES)
def test_lockstep_on_a_graph_equals_the_centralised_run(ros, tmp_path, graph, dim, order,
                                                        method, count, k):
    path = write_scene(tmp_path, graph, dim, order, method, count)
    out, records = tmp_path / "final.npz", tmp_path / "records.jsonl"
    proc = ros.start([PY, "-m", "polymatch_ros.cli", "run", path, "--t-end", str(T_END),
                      "-k", str(k), "--timeout", "150", "--save", str(out),
                      "--run-records", str(records), "-q"], timeout=180)
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
                      "--run-records", str(records), "-k", "1"], timeout=180)
    rc = ros.wait(proc, 190)
    text = ros.output(proc)
    assert rc == 0, text
    assert "converged: matching diameter < 0.001" in text
    m = re.search(r"max vertex deviation ([0-9.e+-]+)", text)
    assert m and float(m.group(1)) <= 1e-9, text
    agents = [r for r in run_records(records.read_text().splitlines()) if r.role == "agent"]
    assert len(agents) == 6 and all(r.finished for r in agents), agents
    assert len({r.steps for r in agents}) == 1 and agents[0].steps < 600   # stopped early
