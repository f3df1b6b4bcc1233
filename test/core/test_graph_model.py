"""Communication graphs in the model (core.graph + core.model): the coupling
kappa/N sum_k a_ik (...) against a naive sum, the complete graph as explicit edges against
the mean field, the Laplacian-mode centroid flow against scipy's expm, per-agent stage
requests against the centralised run, and what the theory does and does not promise."""

import functools
import itertools
import time
from dataclasses import replace

import numpy as np
import pytest
from core_testlib import (
    agents_of_one_row,
    brute_matching_diameter,
    rot_matrices,
    skew_matrices,
)
from scipy import sparse
from scipy.linalg import expm
from scipy.spatial.transform import Rotation

from polymatch_ros.core import load_scene
from polymatch_ros.core.errors import SceneError
from polymatch_ros.core.graph import Graph
from polymatch_ros.core.model import GroupState, State, System
from polymatch_ros.core.so import group_for
from polymatch_ros.core.stepping.integrators import get_method
from polymatch_ros.core.stepping.simulate import convergence_verdict, explain, simulate
from polymatch_ros.core.stepping.solver import drive


def scene(dim=2, order=1, *, graph=None, count=8, seed=1, t_end=2.0, dt=0.02, method="rkmk4",
          rotations="uniform", scales=None, centroids="exact", representation="auto",
          group_graph=None, **group):
    data = {"dimension": dim, "seed": seed,
            "model": {"order": order, "kappa": 1.0, "gamma": 1.0, "centroids": centroids,
                      "representation": representation, **({"mass": 0.5} if order == 2 else {})},
            "integrator": {"method": method, "dt": dt},
            "time": {"t_end": t_end, "samples": {"count": 5}},
            "groups": [{"name": "g", "shape": {"simplex": dim}, "count": count,
                        "rotations": rotations, "centroids": {"box": [-3.0, 3.0]},
                        **{k: v for k, v in group.items() if v is not None}}]}
    if scales is not None:
        data["groups"][0].update(similar=True, scales=scales)
    if group_graph is not None:
        data["groups"][0]["graph"] = group_graph
    if graph is not None:
        data["graph"] = graph
    return load_scene(data)


def final(traj):
    gs = traj.final.groups[0]
    return gs.x, rot_matrices(traj.scene.model.rotations, gs.rot)


COMPLETE_EDGES = {"edges": [list(e) for e in itertools.combinations(range(8), 2)]}


# ---------------------------------------------------------------------------------------------
# the coupling on a graph is the paper's sum with weights a_ik


def naive_rates(model, gs):
    """kappa/(2 gamma N) sum_k a_ik s_k/s_i (O_k O_i^T - O_i O_k^T) and kappa/(gamma N)
    sum_k a_ik (x_k - x_i) (A-2 with F-1 weights), edge by edge, from the raw adjacency."""
    g = model.groups[0]
    a = g.graph.matrix().toarray()
    if g.graph.normalise == "degree":
        a = a * (g.size / a.sum(axis=1))[:, None]
    o = rot_matrices(model.rotations, gs.rot)
    s = np.ones(g.size) if g.scales is None else g.scales
    c = model.kappa / (model.gamma * g.size)
    torque = np.zeros_like(o)
    force = np.zeros_like(gs.x)
    for i, k in zip(*np.nonzero(a)):
        torque[i] += c / 2 * a[i, k] * s[k] / s[i] * (o[k] @ o[i].T - o[i] @ o[k].T)
        force[i] += c * a[i, k] * (gs.x[k] - gs.x[i])
    return torque, force


@pytest.mark.parametrize("dim, rep", [(2, "auto"), (2, "matrix"), (3, "auto"), (3, "matrix"),
                                      (4, "auto")])
@pytest.mark.parametrize("graph", [{"ring": 2}, {"random": {"p": 0.4, "seed": 3}},
                                   {"edges": [[1, 0], [2, 1], [3, 1], [4, 3], [5, 4], [6, 5],
                                              [7, 0], [0, 7]], "directed": True,
                                    "weights": [1, 2, 0.5, 1, 3, 1, 1, 2]},
                                   {"ring": 1, "normalise": "degree"}])
def test_graph_coupling_is_the_weighted_sum_over_neighbours_A_2_F_1(dim, rep, graph):
    sc = scene(dim, graph=graph, representation=rep, centroids="integrated",
               scales={"uniform": [0.5, 2.0]})
    system = System(sc.model)
    gs = sc.initial.groups[0]
    c = system.couple(sc.initial.groups)
    torque, force = naive_rates(sc.model, gs)
    rate = skew_matrices(sc.model.rotations, system.rotation_rate(0, gs.rot, c))
    assert np.max(np.abs(rate - torque)) < 1e-13
    assert np.max(np.abs(system.centroid_force(0, gs.x, c) / sc.model.gamma - force)) < 1e-13


def test_complete_scenes_carry_no_matrix_and_keep_the_mean_field():
    sc = load_scene("congruent_triangles")
    system = System(sc.model)
    assert sc.model.groups[0].graph is None and system.graph_weights == (None,)
    assert type(system.flows[0]).__name__ == "CentroidFlow"
    assert isinstance(system.couple(sc.initial.groups).groups[0].s, complex)   # one S, not N


@pytest.mark.parametrize("dim", [2, 3, 4])
@pytest.mark.parametrize("order", [1, 2])
def test_complete_graph_as_explicit_edges_gives_the_same_trajectory_to_roundoff(dim, order):
    runs = [simulate(scene(dim, order, graph=g, t_end=4.0, dt=0.1))
            for g in (None, COMPLETE_EDGES)]
    (x0, o0), (x1, o1) = (final(t) for t in runs)
    assert runs[0].scene.model.groups[0].graph is None
    assert runs[1].scene.model.groups[0].graph.kind == "edges"
    assert np.max(np.abs(x0 - x1)) < 1e-12 and np.max(np.abs(o0 - o1)) < 1e-12
    assert abs(runs[0].diameters[-1] - runs[1].diameters[-1]) < 1e-11


# ---------------------------------------------------------------------------------------------
# centroids: the exact Laplacian-mode flow (Prop 2.1 generalised)


@pytest.mark.parametrize("order", [1, 2])
@pytest.mark.parametrize("graph", [{"ring": 1}, {"k_nearest": 2},
                                   {"ring": 1, "normalise": "degree"},
                                   {"random": {"p": 0.3, "seed": 2}, "allow_disconnected": True}])
def test_graph_centroid_flow_is_expm_of_the_laplacian_prop_2_1(order, graph):
    sc = scene(3, order, graph=graph, count=10, t_end=3.7, dt=0.1,
               velocities={"centroid": {"normal": 1.0}} if order == 2 else None)
    g = sc.model.groups[0].graph
    a = g.matrix().toarray()
    if g.normalise == "degree":
        a = a / np.where(a.sum(axis=1) > 0, a.sum(axis=1), 1.0)[:, None] * g.size
    lap = (np.diag(a.sum(axis=1)) - a) / g.size           # kappa = gamma = 1
    gs = sc.initial.groups[0]
    traj = simulate(sc)
    x = traj.final.groups[0].x
    if order == 1:
        expected = expm(-3.7 * lap) @ gs.x
    else:                                                 # m x'' = -gamma x' - kappa L x, m = 0.5
        n = g.size
        block = np.block([[np.zeros((n, n)), np.eye(n)], [-lap / 0.5, -np.eye(n) / 0.5]])
        expected = (expm(3.7 * block) @ np.vstack([gs.x, gs.v]))[:n]
    assert np.max(np.abs(x - expected)) < 1e-11 * max(1.0, np.abs(gs.x).max())


@pytest.mark.parametrize("order", [1, 2])
def test_graph_exact_centroids_equal_integrated_ones(order):
    runs = [simulate(scene(2, order, graph={"ring": 1}, centroids=c, t_end=3.0, dt=0.01))
            for c in ("exact", "integrated")]
    assert not runs[1].scene.model.centroids_exact
    assert np.max(np.abs(final(runs[0])[0] - final(runs[1])[0])) < 1e-9
    assert np.max(np.abs(final(runs[0])[1] - final(runs[1])[1])) < 1e-12


def test_directed_graph_integrates_centroids_and_follows_its_root():
    """The root (agent 0) hears no one and never moves, so the limit is its pose whatever the
    step: dt = 1 (h kappa/N = 0.125) ends within 4e-14 of it at t = 400 (bound 1e-6)."""
    chain = {"edges": [[k + 1, k] for k in range(7)], "directed": True}      # 0 -> 1 -> ... -> 7
    sc = scene(2, graph=chain, rotations={"within": 0.5}, t_end=400.0, dt=1.0)
    assert not sc.model.centroids_exact
    traj = simulate(sc)
    root = sc.initial.groups[0]
    x, o = final(traj)
    assert traj.converged
    assert np.max(np.abs(x - root.x[0])) < 1e-6                 # everyone ends at agent 0
    assert np.max(np.abs(o - rot_matrices(sc.model.rotations, root.rot)[0])) < 1e-6
    assert brute_matching_diameter(sc.model, traj.final, 0) < sc.tolerance


# ---------------------------------------------------------------------------------------------
# per-agent stage requests: a lockstep ensemble of single agents equals the centralised run


def lockstep(sc, method, h, steps):
    """Every agent a System of its own row, answered at each stage with only the rows that
    System.sources names (everything else left blank), as the ROS agents will be."""
    model, grp = sc.model, sc.model.rotations
    n = model.groups[0].size

    def sources_only(i, system, req, rows):
        e = GroupState(np.full((n, model.dim), np.nan), grp.identity(n),
                       np.full((n, model.dim), np.nan))
        for f, who in system.sources(0, i, req.boundary).items():
            for k in list(who) + [i]:
                if f == "rot":
                    grp.put(e.rot, [k], rows[k].rot)
                else:
                    getattr(e, f)[k] = getattr(rows[k], f)[0]
        e.x, e.v = np.nan_to_num(e.x), np.nan_to_num(e.v)
        return e

    return agents_of_one_row(sc, method, h, steps, sources_only)


@pytest.mark.parametrize("order, method, centroids", [
    (1, "rkmk4", "exact"), (1, "rkmk4", "integrated"), (2, "rkmk4", "exact"),
    (2, "etd2", "integrated")])
def test_agents_hearing_only_their_sources_equal_the_centralised_run(order, method, centroids):
    sc = scene(3, order, graph={"ring": 1}, count=6, centroids=centroids)
    system = System(sc.model)
    if centroids == "integrated":       # every field comes from the in-neighbours only
        assert all(set(v) == {1, 5} for v in system.sources(0, 0, True).values())
    state = State(0.0, sc.initial.groups)
    for _ in range(5):
        state = drive(get_method(method), system, state, 0.05)
    agents = lockstep(sc, method, 0.05, 5)
    x = np.concatenate([a.groups[0].x for a in agents])
    o = np.concatenate([rot_matrices(sc.model.rotations, a.groups[0].rot) for a in agents])
    assert np.max(np.abs(x - state.groups[0].x)) < 1e-12
    assert np.max(np.abs(o - rot_matrices(sc.model.rotations, state.groups[0].rot))) < 1e-12


# ---------------------------------------------------------------------------------------------
# what is and is not proven on graphs


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("graph", [{"ring": 1}, {"k_nearest": 2},
                                   {"random": {"p": 0.3, "seed": 5}}])
def test_first_order_converges_on_connected_graphs_small_D0_thm_4_2_beyond_paper(dim, graph):
    """Theorem 4.2 assumes the complete graph; on connected graphs the same small-D0 claim
    holds (linear consensus for the centroids, Lohe/Kuramoto near consensus).  dt = 1 (the
    Laplacians' kappa/N lambda_max <= 0.76; rkmk4's limit is 2.78): every case matches at the
    same sample (t = 140 .. 390) as at dt = 0.25, its final diameter within 1e-6 (relative)."""
    sc = scene(dim, graph=graph, count=8, seed=3, rotations={"within": 0.3}, t_end=400.0, dt=1.0)
    traj = simulate(sc, samples=np.linspace(0.0, 400.0, 41), stop_when_converged=True)
    assert traj.metrics[0].groups[0].rotation_diameter < 1.0        # small D0
    assert traj.converged, traj.diameters[-1]
    # the verdict against the vertices: max_{i,j,a} |x^i_a - x^j_a| by brute force
    assert brute_matching_diameter(sc.model, sc.initial, 0) > 100 * sc.tolerance
    assert brute_matching_diameter(sc.model, traj.final, 0) < sc.tolerance


def test_twisted_ring_2d_is_a_stable_equilibrium_held_to_roundoff_and_not_matching():
    """The shipped scene over its whole t_end = 200 (what lets round-off grow if the twist were
    unstable, and the centroids meet), at dt = 0.5 for its 0.05: the linearised rates are at
    most 4 cos(pi/4)/8 = 0.35 (h lambda = 0.18); the centroids' flow is exact either way."""
    sc = load_scene("extremes/twisted_ring_2d")
    traj = simulate(sc, dt=0.5)
    theta = np.asarray(traj.final.groups[0].rot)
    twist = np.angle(np.exp(1j * (theta - 2 * np.pi * np.arange(8) / 8)))
    assert np.max(np.abs(twist)) < 1e-13                     # held at theta_i = 2 pi i / 8
    assert traj.stationarity < 1e-15 and not traj.converged
    assert traj.metrics[-1].groups[0].rotation_diameter > 1.9
    assert traj.metrics[-1].groups[0].centroid_diameter < 1e-4   # the centroids do meet
    assert brute_matching_diameter(sc.model, traj.final, 0) > 1.0   # but the vertices do not
    code, msg = convergence_verdict(sc, traj.diameters[-1], traj.converged_at, traj.stationarity)
    assert code == 0 and "twisted state" in msg and "expected = false" in msg
    sc.expect_convergence = True
    code, msg = convergence_verdict(sc, traj.diameters[-1], traj.converged_at, traj.stationarity)
    assert code == 3 and "twisted state" in msg


@functools.cache
def ring_triangles_run():
    """Fig. 1's scene on a ring (config/ring_triangles.yaml), run until it matches, once for the
    two tests below.  dt = 0.5 for the scene's 0.05: it matches at the same sample (t = 224),
    its diameter there (0.882 of the tolerance) within 6e-7 (relative) of the dt = 0.05 run's."""
    sc = load_scene("ring_triangles")
    return sc, simulate(sc, dt=0.5, stop_when_converged=True)


def test_ring_triangles_figure_1_scene_on_a_ring_converges():
    sc, traj = ring_triangles_run()
    assert sc.model.groups[0].graph.kind == "ring"
    assert traj.converged and traj.converged_at > 50.0         # slower than the complete graph
    assert brute_matching_diameter(sc.model, traj.final, 0) < sc.tolerance
    assert brute_matching_diameter(sc.model, sc.initial, 0) > 1.0


EQUILIBRIUM = "equilibrium that is not consensus"


def test_a_converging_run_is_not_called_an_equilibrium():
    """The verdict names an equilibrium only for a still, unmatched ensemble: a run that
    matches (checked on its vertices) is "converged" and nothing else."""
    sc, traj = ring_triangles_run()
    assert brute_matching_diameter(sc.model, traj.final, 0) < sc.tolerance
    code, msg = convergence_verdict(sc, traj.diameters[-1], traj.converged_at, traj.stationarity,
                                    traj.metrics[-1])
    assert code == 0 and msg.startswith("converged: matching diameter < ")
    assert EQUILIBRIUM not in msg and "did not converge" not in msg


@pytest.mark.parametrize("name", ["ring_triangles", "congruent_triangles"])
def test_a_run_too_short_to_match_is_still_moving_not_an_equilibrium(name):
    """Cut off at t = 1 the ensemble is far from matched and its rotations still turn
    (|W| far from 0): "did not converge", without the equilibrium diagnosis."""
    sc = replace(load_scene(name), t_end=1.0)
    traj = simulate(sc, samples=[0.0, 0.5, 1.0])
    assert traj.final.t == pytest.approx(1.0)
    assert brute_matching_diameter(sc.model, traj.final, 0) > 100 * sc.tolerance
    assert traj.stationarity > 1e-3
    code, msg = convergence_verdict(sc, traj.diameters[-1], traj.converged_at, traj.stationarity,
                                    traj.metrics[-1])
    assert code == 3 and msg.startswith("did not converge: matching diameter ")
    assert EQUILIBRIUM not in msg and "twisted" not in msg


# ---------------------------------------------------------------------------------------------
# disconnected graphs: refused, or accepted and reported per component


def test_disconnected_graph_is_refused_in_one_line_naming_components():
    with pytest.raises(SceneError, match=r"^graph \(groups\[0\]\): the graph is disconnected: "
                                         r"components \{0, 1, 2, 3\} \{4, 5, 6, 7\}$"):
        scene(graph={"edges": [[0, 1], [1, 2], [2, 3], [4, 5], [5, 6], [6, 7]]})
    with pytest.raises(SceneError, match=r"^groups\[0\]\.graph: no agent reaches all others"):
        scene(graph="complete", group_graph={"edges": [[1, 0], [1, 2]], "directed": True})


def test_allow_disconnected_reports_each_components_diameter():
    spec = {"edges": [[0, 1], [1, 2], [2, 3], [4, 5], [5, 6], [6, 7]], "allow_disconnected": True}
    # dt = 1 (the paths' kappa/N lambda_max = 0.43): the parts end at 1.3e-9, as at dt = 0.1
    sc = scene(graph=spec, rotations={"within": 0.3}, t_end=300.0, dt=1.0)
    traj = simulate(sc)
    parts = traj.metrics[-1].component_diameters[0]
    assert len(parts) == 2 and max(parts) < 1e-6           # each component matches itself
    assert traj.diameters[-1] > 1e-3 and not traj.converged  # but the group does not match as one
    assert brute_matching_diameter(sc.model, traj.final, 0) > 1e-3
    code, msg = convergence_verdict(sc, traj.diameters[-1], traj.converged_at, traj.stationarity,
                                    traj.metrics[-1])
    assert code == 3 and "component diameters [" in msg
    assert any("2 components (allow_disconnected)" in line for line in explain(sc))


@pytest.mark.parametrize("graph, message", [
    ("star", r"^graph: unknown graph 'star'"),
    ({"ring": 1, "normalise": "mean"}, r"^graph\.normalise: expected size or degree"),
    ({"ring": 1, "allow_disconnected": "yes"},
     r"^graph\.allow_disconnected: expected true or false"),
    ({"k_nearest": 8}, r"^graph\.k_nearest: must be < the group's 8 agents"),
])
def test_bad_scene_graphs_are_one_line_scene_errors(graph, message):
    with pytest.raises(SceneError, match=message):
        scene(graph=graph)
    with pytest.raises(SceneError, match=message.replace(r"^graph", r"^groups\[0\]\.graph")):
        scene(group_graph=graph)


def test_group_graph_overrides_the_scene_default():
    sc = scene(graph={"ring": 1}, group_graph="complete")
    assert sc.model.groups[0].graph is None
    lines = explain(scene(graph={"ring": 1}))
    assert any("'g' graph: ring, |E| = 16" in line and "O(|E| d^2 + N d^3)" in line
               for line in lines)


# ---------------------------------------------------------------------------------------------
# cost: O(|E| d^2 + N d^3) per evaluation


def complete_adjacency(n):
    """The complete graph's n x n CSR adjacency (every k != i in row i), built from its indices:
    csr_matrix(ones - eye) scans 4e6 dense entries at n = 2000, slowly."""
    k = np.arange(n - 1)[None, :]
    cols = k + (k >= np.arange(n)[:, None])              # row i: 0 .. i-1, i+1 .. n-1
    return sparse.csr_matrix((np.ones(n * (n - 1)), cols.ravel(), np.arange(n + 1) * (n - 1)),
                             shape=(n, n))


def test_ring_evaluation_is_cheaper_than_complete_edges_at_n_2000():
    n, grp = 2000, group_for(3)
    rot = grp.from_matrices(Rotation.random(n, random_state=0).as_matrix())
    ring = Graph("ring", n, sparse.csr_matrix(sparse.diags([1.0, 1.0, 1.0, 1.0],
                                                           [-1, 1, n - 1, 1 - n], (n, n))))
    complete = Graph("edges", n, complete_adjacency(n))

    def cost(graph):
        w = graph.local_weights()
        best = np.inf
        for _ in range(3):
            t0 = time.perf_counter()
            grp.coupling(rot, grp.neighbour_fields(rot, w.rot))
            best = min(best, time.perf_counter() - t0)
        return best

    ratio = cost(ring) / cost(complete)
    print(f"ring / complete-edges evaluation at N = {n}: {ratio:.3g}")
    assert ring.edge_count == 2 * n and complete.edge_count == n * (n - 1)
    assert ratio < 0.25


def test_cli_refuses_a_disconnected_graph_exit_2_and_reports_the_twisted_ring(tmp_path, capsys):
    from polymatch_ros.cli import main
    path = tmp_path / "disconnected.yaml"
    path.write_text("dimension: 2\ngraph: {edges: [[0, 1], [2, 3]]}\n"
                    "groups:\n  - {shape: triangle, count: 4}\n")
    assert main(["simulate", str(path), "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["polymatch: error: graph (groups[0]): the graph is disconnected: "
                   "components {0, 1} {2, 3}"]
    twisted = ["extremes/twisted_ring_2d", "-q", "--t-end", "20", "--dt", "0.5"]   # 10x its dt:
    assert main(["simulate", *twisted]) == 0            # the twist is held at any step
    assert "twisted state" in capsys.readouterr().out


@pytest.mark.parametrize("order", [1, 2])
def test_adaptive_run_on_a_graph_agrees_with_rkmk4(order):
    """rkmk4 at dt = 0.02 ends 3e-13 (x) and 5e-11 (O) from the adaptive run at tolerance
    1e-10, against the bounds 1e-9 and 1e-7."""
    runs = [simulate(scene(3, order, graph={"k_nearest": 2}, t_end=3.0, dt=0.02), method=m,
                     tolerance=1e-10 if m == "adaptive" else None) for m in ("rkmk4", "adaptive")]
    (x0, o0), (x1, o1) = (final(t) for t in runs)
    assert np.max(np.abs(x0 - x1)) < 1e-9 and np.max(np.abs(o0 - o1)) < 1e-7
