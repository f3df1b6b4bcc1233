"""Which peers a distributed agent reads on a graph: its in-neighbours where the centroids are
integrated with the stages, everyone where their exact flow reads every centroid (and the
blocks a packed process sends and reads)."""

from polymatch_ros.core.model import System
from polymatch_ros.core.scenes.scene import load_scene
from polymatch_ros.ros.wire.intake import Layout

SCENE = """\
name: graph_case
dimension: {dim}
seed: 4
model: {{order: 1, kappa: 1.0, gamma: 1.0}}
graph: {graph}
integrator: {{method: rkmk4, dt: 0.05}}
time: {{t_end: 5.0}}
groups:
  - {{name: g, shape: {{simplex: {dim}}}, count: {count}, centroids: {{box: [-3.0, 3.0]}},
      rotations: uniform}}
"""


def write_scene(tmp_path, graph, dim, order, method, count):
    assert (order, method) == (1, "rkmk4")
    path = tmp_path / "graph_case.yaml"
    path.write_text(SCENE.format(dim=dim, graph=graph, count=count))
    return str(path)


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
