"""Proximity graphs (``graph: {radius: R}``, core.proximity): the KD-tree's weights against
brute-force distances, the right-hand sides of (A-1), (A-2), (F-1) against a naive pair sum,
the integrators' order with the smooth and the hard cut-off, one-row agents against the
centralised run, the cost per evaluation, and the shipped scenes that stay connected and that
split (union graph connected over time: Jadbabaie, Lin & Morse 2003; Moreau 2005)."""

import time

import numpy as np
import pytest
from core_testlib import agents_of_one_row, rot_matrices
from scipy.sparse import csgraph
from scipy.spatial.distance import cdist, pdist, squareform

from polymatch_ros.core import load_scene, proximity
from polymatch_ros.core.errors import SceneError
from polymatch_ros.core.graph import Graph
from polymatch_ros.core.model import GroupState, State, System
from polymatch_ros.core.so import group_for
from polymatch_ros.core.stepping.integrators import check_stability, get_method, max_stable_dt
from polymatch_ros.core.stepping.simulate import convergence_verdict, explain, simulate
from polymatch_ros.core.stepping.solver import drive


def brute_weights(x, radius, cutoff="smooth"):
    """a_ik from every pairwise distance (scipy's cdist), written from the documented formula."""
    r = cdist(x, x) / radius
    a = np.zeros_like(r)
    inside = r < 1.0
    np.fill_diagonal(inside, False)
    a[inside] = 1.0 if cutoff == "hard" else np.exp(1.0 - 1.0 / (1.0 - r[inside] ** 2))
    return a


def brute_parts(x, radius, first=0):
    """The components of the pairs closer than radius, from the full distance matrix."""
    n, labels = csgraph.connected_components(squareform(pdist(x) < radius), directed=False)
    return tuple(sorted(tuple(int(first + i) for i in np.flatnonzero(labels == c))
                        for c in range(n)))


def scene(dim=2, order=1, *, radius=2.0, cutoff="smooth", count=5, seed=3, box=1.6, kappa=4.0,
          scales=None, **extra):
    group = {"name": "g", "shape": {"simplex": dim}, "count": count,
             "centroids": {"box": [-box, box]}, "rotations": "uniform"}
    if order == 2:
        group["velocities"] = {"centroid": {"normal": 0.5}, "angular": {"normal": 0.3}}
    if scales is not None:
        group.update(similar=True, scales=scales)
    return load_scene({"dimension": dim, "seed": seed,
                       "graph": {"radius": radius, "cutoff": cutoff, **extra},
                       "model": {"order": order, "kappa": kappa, "gamma": 1.0,
                                 **({"mass": 0.5} if order == 2 else {})},
                       "integrator": {"method": "rkmk4", "dt": 0.05}, "time": {"t_end": 2.0},
                       "groups": [group]})


# ---------------------------------------------------------------------------------------------
# the weights: KD-tree against brute force


@pytest.mark.parametrize("n, dim", [(600, 3), (40, 2)])        # the KD-tree, and SMALL's path
@pytest.mark.parametrize("cutoff", ["smooth", "hard"])
def test_kd_tree_weights_and_components_equal_brute_force(n, dim, cutoff):
    rng = np.random.default_rng(7)
    x = rng.random((n, dim)) * (n ** (1 / dim))                 # about 4-10 neighbours each
    radius = 1.3
    want = brute_weights(x, radius, cutoff)
    a, rot, sums = proximity.weight_matrix(x, radius, cutoff)
    dense = a.toarray() if hasattr(a, "toarray") else a
    assert np.max(np.abs(dense - want)) < 1e-15 and np.count_nonzero(want) > 2 * n
    assert np.max(np.abs(sums - want.sum(axis=1))) < 1e-13
    assert rot is a                                             # no F-1 scales
    rows = np.array([0, 5, 17, n - 1])
    part, _, part_sums = proximity.weight_matrix(x, radius, cutoff, rows)
    assert np.array_equal(np.asarray(part), dense[rows])        # an agent's rows: the same numbers
    assert np.array_equal(part_sums, sums[rows])
    graph = Graph("radius", n, None, radius=radius, cutoff=cutoff)
    assert proximity.parts_of(np.arange(n), graph.components_at(x)) == brute_parts(x, radius)
    scale = rng.uniform(0.5, 2.0, n)
    _, rot, _ = proximity.weight_matrix(x, radius, cutoff, scale=scale)
    rot = rot.toarray() if hasattr(rot, "toarray") else rot
    assert np.max(np.abs(rot - want * scale[None, :])) < 1e-15


def test_the_bump_falls_smoothly_to_zero_at_the_radius_and_is_one_at_distance_zero():
    r = np.array([0.0, 0.5, 0.9, 0.999, 1.0, 1.5])
    w = proximity.bump(r ** 2, 1.0)
    assert w[0] == 1.0 and w[4] == 0.0 and w[5] == 0.0
    assert np.all(np.diff(w) <= 0) and w[1] == pytest.approx(np.exp(1 - 1 / 0.75))
    assert w[3] < 1e-200                                       # flat at R: every derivative is 0
    assert list(proximity.bump(r ** 2, 1.0, "hard")) == [1, 1, 1, 1, 0, 0]


def test_one_evaluation_costs_n_log_n_not_n_squared():
    """The centralised evaluation at N = 16000 costs about 16x (N log N: ~20x) the one at 1000,
    far from the 256x of every pair (density fixed: about 7 neighbours each)."""
    grp = group_for(2)

    def cost(n):
        rng = np.random.default_rng(0)
        x, theta = rng.random((n, 2)) * np.sqrt(n), rng.uniform(0, 2 * np.pi, n)
        graph = Graph("radius", n, None, radius=1.5)
        best = np.inf
        for _ in range(3):
            t0 = time.process_time()
            w = graph.weights_at(x)
            grp.coupling(theta, grp.neighbour_fields(theta, w.rot))
            best = min(best, time.process_time() - t0)
        return best, w.p.nnz / n

    (small, _), (large, degree) = cost(1000), cost(16000)
    print(f"per evaluation: N = 1000 {small * 1e3:.2f} ms, N = 16000 {large * 1e3:.2f} ms "
          f"({large / small:.1f}x), mean degree {degree:.1f}")
    assert 4 < degree < 12 and large / small < 64


# ---------------------------------------------------------------------------------------------
# the right-hand sides, (A-2), (F-1) with a_ik(x)


def naive_rates(model, gs):
    """kappa/(2N) sum_k a_ik s_k/s_i (O_k O_i^T - O_i O_k^T) and kappa/N sum_k a_ik (x_k - x_i),
    pair by pair with a_ik from brute-force distances."""
    g = model.groups[0]
    a = brute_weights(gs.x, g.graph.radius, g.graph.cutoff)
    o = rot_matrices(model.rotations, gs.rot)
    s = np.ones(g.size) if g.scales is None else g.scales
    torque, force = np.zeros_like(o), np.zeros_like(gs.x)
    for i, k in zip(*np.nonzero(a)):
        torque[i] += model.kappa / (2 * g.size) * a[i, k] * s[k] / s[i] * (
            o[k] @ o[i].T - o[i] @ o[k].T)
        force[i] += model.kappa / g.size * a[i, k] * (gs.x[k] - gs.x[i])
    return torque, force


@pytest.mark.parametrize("dim, order, scales", [(2, 1, None), (3, 1, {"uniform": [0.5, 2.0]}),
                                                (3, 2, None), (2, 2, {"uniform": [0.5, 2.0]})])
def test_rates_are_the_pair_sums_with_proximity_weights_A_1_A_2_F_1(dim, order, scales):
    sc = scene(dim, order, count=9, box=2.0, scales=scales)
    m, gs = sc.model, sc.initial.groups[0]
    a = brute_weights(gs.x, 2.0)
    assert 0 < np.count_nonzero(a) < 9 * 8                     # some pairs in range, not all
    system = System(m)
    k_rot, k_x, k_v, k_w = system.rates(State(0.0, (gs,)), system.couple((gs,)))[0]
    torque, force = naive_rates(m, gs)
    skew = m.rotations.algebra_to_skew
    if order == 1:                                             # (A-2): W_i and x_i' over gamma
        assert np.max(np.abs(skew(k_rot) - torque / m.gamma)) < 1e-13
        assert np.max(np.abs(k_x - force / m.gamma)) < 1e-13
    else:                                                      # (A-1): m W' = -gamma W + torque
        want_w = (torque - m.gamma * skew(gs.w)) / m.mass
        assert np.max(np.abs(skew(k_w) - want_w)) < 1e-13
        assert np.max(np.abs(k_v - (force - m.gamma * gs.v) / m.mass)) < 1e-13
        assert np.array_equal(k_x, gs.v)


# ---------------------------------------------------------------------------------------------
# smoothness: the order of the integrators across pairs entering the range


def pairs_in_range(x, radius):
    return {tuple(p) for p in np.argwhere(np.triu(squareform(pdist(x) < radius), 1))}


@pytest.mark.parametrize("order, cutoff", [(1, "smooth"), (2, "smooth"), (1, "hard")])
def test_rkmk4_keeps_order_4_with_the_smooth_cutoff_and_drops_to_1_with_the_hard_one(order,
                                                                                       cutoff):
    """Pairs come into range during the run (checked); the C-infinity bump keeps the right-hand
    side smooth, so the errors against a fine run fall as h^4; the hard cut-off's right-hand side
    jumps there, and they fall as h."""
    sc = scene(2, order, cutoff=cutoff)
    method, system, t_end = get_method("rkmk4"), System(sc.model), 2.0

    def final(n):
        state = State(0.0, sc.initial.groups)
        for _ in range(n):
            state = drive(method, system, state, t_end / n)
        gs = state.groups[0]
        return gs.x, np.concatenate([gs.x.ravel(), rot_matrices(sc.model.rotations,
                                                                gs.rot).ravel()])

    x_end, ref = final(320)
    assert pairs_in_range(sc.initial.groups[0].x, 2.0) < pairs_in_range(x_end, 2.0)
    steps = np.array([10, 20, 40, 80])
    errors = [np.max(np.abs(final(n)[1] - ref)) for n in steps]
    slope = -np.polyfit(np.log(steps), np.log(errors), 1)[0]
    shown = ", ".join(f"{e:.2e}" for e in errors)
    print(f"order {order}, {cutoff} cut-off: errors at 10-80 steps {shown}, observed order "
          f"{slope:.2f}")
    if cutoff == "smooth":
        assert slope > 3.7
    else:
        assert 0.5 < slope < 1.5


# ---------------------------------------------------------------------------------------------
# one process per agent: every peer's stage values, the same weights


def one_row_agents(sc, method, h, steps):
    """Every agent a System of its own row, answered at each stage with every agent's stage
    values (what a lockstep agent assembles from its peers' stage messages)."""
    model, grp = sc.model, sc.model.rotations
    n = model.groups[0].size
    systems = [System(model, [[i]]) for i in range(n)]
    assert all(set(systems[0].sources(0, 0, first)["x"]) == set(range(1, n))
               for first in (True, False))                    # any peer may come into range

    def every_peer(i, system, req, rows):
        return GroupState(np.concatenate([r.x for r in rows]), grp.concat([r.rot for r in rows]),
                          None if rows[0].v is None else np.concatenate([r.v for r in rows]))

    return agents_of_one_row(sc, method, h, steps, every_peer)


@pytest.mark.parametrize("order, method", [(1, "rkmk4"), (2, "rkmk4"), (2, "etd2")])
def test_one_row_agents_equal_the_centralised_run_to_roundoff(order, method):
    sc = scene(3, order, count=6, box=1.4)
    state = State(0.0, sc.initial.groups)
    for _ in range(10):
        state = drive(get_method(method), System(sc.model), state, 0.05)
    agents = one_row_agents(sc, method, 0.05, 10)
    x = np.concatenate([a.groups[0].x for a in agents])
    o = np.concatenate([rot_matrices(sc.model.rotations, a.groups[0].rot) for a in agents])
    assert np.max(np.abs(x - state.groups[0].x)) < 1e-13
    assert np.max(np.abs(o - rot_matrices(sc.model.rotations, state.groups[0].rot))) < 1e-13
    assert np.max(np.abs(x - sc.initial.groups[0].x)) > 0.05  # they moved


# ---------------------------------------------------------------------------------------------
# the scene key, the step check, explain


@pytest.mark.parametrize("graph, message", [
    ({"radius": -1.0}, r"^graph\.radius: must be >= 1e-12, got -1\.0$"),
    ({"radius": "far"}, r"^graph\.radius: expected a number"),
    ({"radius": 2.0, "cutoff": "soft"}, r"^graph\.cutoff: expected smooth or hard, got 'soft'$"),
    ({"ring": 1, "cutoff": "hard"}, r"^graph\.cutoff: a cut-off goes with radius$"),
    ({"radius": 2.0, "normalise": "degree"}, r"^graph\.normalise: a proximity graph normalises"),
    ({"radius": 2.0, "weights": [1.0]}, r"^graph: weights and directed go with edges$"),
    ({"radius": 0.3}, r"^graph \(groups\[0\]\): the proximity graph \(radius 0\.3\) is "
                      r"disconnected at the start: components \{0\} \{1\} \{2\} \{3\} and 1 more"),
])
def test_bad_radius_graphs_are_one_line_scene_errors(graph, message):
    with pytest.raises(SceneError, match=message):
        load_scene({"dimension": 2, "graph": graph, "seed": 3,
                    "groups": [{"shape": "triangle", "count": 5,
                                "centroids": {"box": [-1.6, 1.6]}}]})


def test_the_step_check_is_the_complete_graphs_at_consensus_and_explain_names_the_kd_tree():
    """At consensus every pair is at distance 0 with weight 1: the complete graph's linearisation,
    so the stability limits are the complete scene's."""
    sc = scene(2, 2, kappa=30.0)
    complete = load_scene({"dimension": 2, "seed": 3, "model": {"order": 2, "kappa": 30.0,
                                                                "gamma": 1.0, "mass": 0.5},
                           "groups": [{"shape": "triangle", "count": 5,
                                       "centroids": {"box": [-1.6, 1.6]}}]})
    assert not sc.model.centroids_exact                        # a nonlinear consensus
    for name in ("rkmk4", "lie_euler"):
        method = get_method(name)
        # the complete scene solves its centroids exactly: its rotations' limit is the same
        assert max_stable_dt(method, sc.model, 10.0) == max_stable_dt(method, complete.model, 10.0)
    with pytest.raises(Exception, match="unstable at dt"):
        check_stability(get_method("lie_euler"), sc.model, 0.5)
    lines = explain(sc)
    assert any("proximity, radius R = 2" in line and "KD-tree" in line for line in lines)
    assert any("centroids: integrated" in line and "proximity graph" in line for line in lines)


# ---------------------------------------------------------------------------------------------
# the shipped scenes: one stays connected and matches, one splits


def test_radio_connected_stays_one_component_and_matches():
    sc = load_scene("radio_connected")
    traj = simulate(sc, stop_when_converged=True)
    first = pairs_in_range(sc.initial.groups[0].x, 5.0)
    assert len(first) == 19 and traj.converged                 # 9 pairs come into range
    for st in traj.states:                                     # one component at every sample
        assert len(brute_parts(st.groups[0].x, 5.0)) == 1
    assert [c.parts for c in traj.component_history] == [(tuple(range(8)),)]
    assert convergence_verdict(sc, traj.diameters[-1], traj.converged_at)[0] == 0


def test_radio_fragments_splits_and_says_which_agents_from_when_exit_3(capsys):
    sc = load_scene("radio_fragments", {"time.t_end": 6.0})
    traj = simulate(sc)
    brute = [brute_parts(st.groups[0].x, 4.0) for st in traj.states]
    split_at = next(i for i, parts in enumerate(brute) if len(parts) > 1)
    assert len(brute[0]) == 1 and all(p == brute[split_at] for p in brute[split_at:])
    (final,) = traj.components
    assert final.parts == brute[-1] == ((0, 4, 6, 7), (1, 2, 3, 5))
    assert final.since == traj.times[split_at] == 2.0
    code, msg = convergence_verdict(sc, traj.diameters[-1], traj.converged_at, traj.stationarity,
                                    traj.metrics[-1], traj.components)
    assert code == 3 and "\n" not in msg
    assert ("group 'triangles' split into 2 components {0, 4, 6, 7} {1, 2, 3, 5} (radius 4) "
            "from t = 2, component diameters [") in msg
    assert "Jadbabaie, Lin & Morse 2003; Moreau 2005" in msg and "twisted" not in msg
    sc.expect_convergence = False
    assert convergence_verdict(sc, traj.diameters[-1], traj.converged_at,
                               components=traj.components)[0] == 0
    from polymatch_ros.cli import main
    assert main(["simulate", "radio_fragments", "-q", "--t-end", "3"]) == 3
    out = capsys.readouterr().out.strip().splitlines()
    assert out[-1].startswith("did not converge") and "{0, 4, 6, 7} {1, 2, 3, 5}" in out[-1]
