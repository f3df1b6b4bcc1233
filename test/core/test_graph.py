"""Communication graphs (core.graph): the complete graph is the paper's mean field exactly, the
other specifications build the adjacency they name, and graphs on which a group cannot match as
one are refused with the components named."""

import itertools

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from polymatch_ros.core.errors import SceneError
from polymatch_ros.core.graph import build_graph, check_connected


def _torques(graph, rots):
    """sum_k a_ik (O_k O_i^T - O_i O_k^T) through the graph's weighted sums (eq. A-2's sum)."""
    s = graph.weighted_sums(rots)
    return s @ np.swapaxes(rots, 1, 2) - rots @ np.swapaxes(s, 1, 2)


def test_complete_graph_is_the_mean_field_of_a2():
    rots = Rotation.random(7, random_state=3).as_matrix()
    graph = build_graph("complete", "graph", 7)
    s = rots.sum(axis=0)
    mean_field = s @ np.swapaxes(rots, 1, 2) - rots @ s.T
    assert graph.complete and graph.weights is None
    assert np.max(np.abs(_torques(graph, rots) - mean_field)) < 1e-14
    naive = np.array([sum(rots[k] @ rots[i].T - rots[i] @ rots[k].T for k in range(7))
                     for i in range(7)])
    assert np.max(np.abs(mean_field - naive)) < 1e-13


def test_complete_graph_as_explicit_edges_gives_the_same_sums():
    n = 6
    edges = [[i, k] for i, k in itertools.combinations(range(n), 2)]
    explicit = build_graph({"edges": edges}, "graph", n)
    complete = build_graph("complete", "graph", n)
    x = np.random.default_rng(0).normal(size=(n, 3))
    rots = Rotation.random(n, random_state=1).as_matrix()
    assert np.max(np.abs(explicit.weighted_sums(x) - complete.weighted_sums(x))) < 1e-14
    assert np.max(np.abs(_torques(explicit, rots) - _torques(complete, rots))) < 1e-14
    assert np.array_equal(explicit.degrees(), complete.degrees())


def test_ring_links_k_neighbours_on_each_side():
    graph = build_graph({"ring": 2}, "graph", 10)
    assert np.array_equal(graph.degrees(), np.full(10, 4.0))
    assert sorted(graph.in_neighbours(0)) == [1, 2, 8, 9]
    assert (graph.matrix() != graph.matrix().T).nnz == 0
    check_connected(graph, "graph")


def test_k_nearest_is_the_undirected_union_of_nearest_neighbours():
    centroids = np.array([[0.0, 0], [1, 0], [10, 0], [11, 0], [5.2, 0]])
    graph = build_graph({"k_nearest": 1}, "graph", 5, centroids)
    a = graph.matrix().toarray()
    assert np.array_equal(a, a.T)
    # nearest: 0 <-> 1, 2 <-> 3, and 4 -> 1 (4.2 away, against 4.8 to agent 2);
    # the union is symmetric
    expected = {(0, 1), (1, 0), (2, 3), (3, 2), (4, 1), (1, 4)}
    assert {(int(i), int(k)) for i, k in zip(*np.nonzero(a))} == expected


def test_random_graph_is_reproducible_and_its_extremes_are_empty_and_complete():
    g1 = build_graph({"random": {"p": 0.5, "seed": 4}}, "graph", 12)
    g2 = build_graph({"random": {"p": 0.5, "seed": 4}}, "graph", 12)
    assert (g1.matrix() != g2.matrix()).nnz == 0
    full = build_graph({"random": {"p": 1.0, "seed": 0}}, "graph", 5).matrix().toarray()
    assert np.array_equal(full, np.ones((5, 5)) - np.eye(5))
    empty = build_graph({"random": {"p": 0.0}}, "groups[0].graph", 5)
    with pytest.raises(SceneError, match=r"^groups\[0\]\.graph: the graph is disconnected: "
                                         r"components \{0\} \{1\}"):
        check_connected(empty, "groups[0].graph")


def test_disconnected_undirected_graph_is_refused_naming_components():
    graph = build_graph({"edges": [[0, 1], [2, 3]]}, "graph", 4)
    with pytest.raises(SceneError, match=r"disconnected: components \{0, 1\} \{2, 3\}"):
        check_connected(graph, "graph")


def test_directed_graph_needs_an_agent_that_reaches_all():
    chain = build_graph({"edges": [[1, 0], [2, 1]], "directed": True}, "graph", 3)   # 0 -> 1 -> 2
    check_connected(chain, "graph")
    assert list(chain.in_neighbours(2)) == [1] and list(chain.in_neighbours(0)) == []
    two_sources = build_graph({"edges": [[1, 0], [1, 2]], "directed": True}, "graph", 3)
    with pytest.raises(SceneError, match=r"no agent reaches all others .*\{0\}; \{2\}"):
        check_connected(two_sources, "graph")


def test_weights_scale_the_sums():
    graph = build_graph({"edges": [[0, 1], [1, 2]], "weights": [2.0, 0.5]}, "graph", 3)
    x = np.array([[1.0], [10.0], [100.0]])
    assert graph.weighted_sums(x).ravel().tolist() == [20.0, 2 * 1.0 + 0.5 * 100.0, 5.0]


@pytest.mark.parametrize("spec, message", [
    ("star", r"graph: unknown graph 'star'"),
    ({"ring": 0}, r"graph\.ring: must be >= 1"),
    ({"ring": 1, "k_nearest": 1}, r"graph: expected exactly one of"),
    ({"k_nearest": 5}, r"graph\.k_nearest: must be < the group's 5 agents"),
    ({"random": {"p": 1.5}}, r"graph\.random\.p: must be <= 1"),
    ({"edges": [[0, 0]]}, r"graph\.edges\[0\]: an agent is not its own neighbour"),
    ({"edges": [[0, 7]]}, r"graph\.edges\[0\]: agent indices must be < the group's 5 agents"),
    ({"edges": [[0, 1]], "weights": [1, 2]},
     r"graph\.weights: expected one positive weight per edge"),
    ({"edges": [[0, 1]], "weights": [-1]}, r"graph\.weights\[0\]: must be > 0"),
    ({"ring": 1, "directed": True}, r"graph: weights and directed go with edges"),
])
def test_bad_graph_specifications_are_one_line_scene_errors(spec, message):
    with pytest.raises(SceneError, match=message):
        build_graph(spec, "graph", 5, np.zeros((5, 2)) + np.arange(5)[:, None])
