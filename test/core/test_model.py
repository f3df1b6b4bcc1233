"""Right-hand sides of the paper's models against direct transcriptions of the formulas.

(A-2)  W_i = kappa/(2 gamma N) sum_k (O_k O_i^T - O_i O_k^T)
(A-1)  m W_i' = -gamma W_i + kappa/(2N) sum_k (O_k O_i^T - O_i O_k^T)
(F-1)  torque weights s_k / s_i
(F-2)  kappa_1/N_1 sum_k (x_k - x_i) + kappa_2/N_2 sum_l (|y_l - x_i| - L)(y_l - x_i)/|y_l - x_i|
Prop. 2.1: the centroid flow is the exact solution of a linear system (expm).
"""

import numpy as np
import pytest
from core_testlib import make_scene, rot_matrices, skew_matrices
from scipy.linalg import expm

from polymatch_ros.core import System, load_scene
from polymatch_ros.core.model import CentroidFlow, pair_force

REPRESENTATIONS = [(2, "angle"), (2, "matrix"), (3, "so3"), (3, "so3-exp"), (3, "matrix"),
                   (4, "matrix"), (5, "matrix")]


def naive_lohe_sum(mats, weights=None):
    """sum_k w_k/w_i (O_k O_i^T - O_i O_k^T) for every i, as an explicit O(N^2) double loop."""
    n = len(mats)
    w = np.ones(n) if weights is None else np.asarray(weights, dtype=float)
    out = np.zeros_like(mats)
    for i in range(n):
        for k in range(n):
            out[i] += (w[k] / w[i]) * (mats[k] @ mats[i].T - mats[i] @ mats[k].T)
    return out


def _coupling(system, state):
    return system.couple(state.groups)


@pytest.mark.parametrize("dim,rep", REPRESENTATIONS, ids=[f"{r}-{d}d" for d, r in REPRESENTATIONS])
def test_mean_field_equals_naive_lohe_sum_first_order_A_2(dim, rep):
    kappa, gamma, n = 1.7, 2.3, 7
    scene = make_scene(dim, 1, count=n, seed=11, representation=rep, kappa=kappa, gamma=gamma)
    model = scene.model
    assert model.rotations.name == rep.split("-")[0]
    system = System(model)
    gs = scene.initial.groups[0]
    rate = system.rotation_rate(0, gs.rot, _coupling(system, scene.initial))
    expected = kappa / (2.0 * gamma * n) * naive_lohe_sum(rot_matrices(model.rotations, gs.rot))
    got = skew_matrices(model.rotations, rate)
    assert np.max(np.abs(expected)) > 0.1            # the ensemble is far from consensus
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-13)
    # rates(): first order has no velocities, k_rot = W_i
    k_rot, k_x, k_v, k_w = system.rates(scene.initial, _coupling(system, scene.initial))[0]
    np.testing.assert_allclose(skew_matrices(model.rotations, k_rot), expected, rtol=0, atol=1e-13)
    assert k_x is None and k_v is None and k_w is None   # centroids solved exactly, no W state


@pytest.mark.parametrize("dim,rep", REPRESENTATIONS, ids=[f"{r}-{d}d" for d, r in REPRESENTATIONS])
def test_mean_field_equals_naive_torque_second_order_A_1(dim, rep):
    kappa, gamma, mass, n = 1.3, 0.7, 0.4, 6
    scene = make_scene(dim, 2, count=n, seed=12, representation=rep, kappa=kappa, gamma=gamma,
                       mass=mass,
                       velocities={"angular": {"normal": 0.8}, "centroid": {"normal": 0.5}})
    model = scene.model
    system = System(model)
    gs = scene.initial.groups[0]
    coupling = _coupling(system, scene.initial)
    torque = kappa / (2.0 * n) * naive_lohe_sum(rot_matrices(model.rotations, gs.rot))
    rate = system.rotation_rate(0, gs.rot, coupling)
    np.testing.assert_allclose(skew_matrices(model.rotations, rate), torque, rtol=0, atol=1e-13)
    # O' = W O and m W' = -gamma W + torque
    k_rot, k_x, k_v, k_w = system.rates(scene.initial, coupling)[0]
    w = skew_matrices(model.rotations, gs.w)
    assert np.max(np.abs(w)) > 0.1
    np.testing.assert_allclose(skew_matrices(model.rotations, k_rot), w, rtol=0, atol=1e-15)
    np.testing.assert_allclose(skew_matrices(model.rotations, k_w), (torque - gamma * w) / mass,
                               rtol=0, atol=1e-12)


@pytest.mark.parametrize("order", [1, 2])
@pytest.mark.parametrize("dim", [2, 3, 4])
def test_similar_torque_weights_match_paper_F_1(dim, order):
    kappa, gamma, n = 1.1, 1.6, 6
    scene = make_scene(dim, order, count=n, seed=13, kappa=kappa, gamma=gamma, mass=0.3,
                       scales={"log_uniform": [0.2, 5.0]})
    model = scene.model
    s = model.groups[0].scales
    assert s is not None and np.ptp(s) > 0.5
    system = System(model)
    gs = scene.initial.groups[0]
    rate = system.rotation_rate(0, gs.rot, _coupling(system, scene.initial))
    scale = kappa / (2.0 * n) if order == 2 else kappa / (2.0 * gamma * n)
    expected = scale * naive_lohe_sum(rot_matrices(model.rotations, gs.rot), weights=s)
    np.testing.assert_allclose(skew_matrices(model.rotations, rate), expected, rtol=0, atol=1e-12)
    # the weights are not symmetric: with s_i all equal the result would differ
    unweighted = scale * naive_lohe_sum(rot_matrices(model.rotations, gs.rot))
    assert np.max(np.abs(unweighted - expected)) > 1e-3


# ---------------------------------------------------------------------------------------------
# F-2


def paper_f2_force(xs, gi, i, kappa_1, kappa_2, L):
    """The paper's F-2 centroid force on agent i of group gi, transcribed term by term.

    Coincident centroids (|y_l - x_i| = 0) contribute zero: the core's documented choice.
    """
    x = xs[gi]
    xi = x[i]
    force = kappa_1 / len(x) * sum(x[k] - xi for k in range(len(x)))
    for hi, y in enumerate(xs):
        if hi == gi:
            continue
        for yl in y:
            r = float(np.sqrt(np.sum((yl - xi) ** 2)))
            if r > 0.0:
                force = force + kappa_2 / len(y) * (r - L) * (yl - xi) / r
    return force


def _mixed_scene(order, centroids=None, dim=2):
    shapes = (["triangle", "square", "pentagon"] if dim == 2
              else ["triangle", "tetrahedron", "cube"])
    counts = [3, 4, 5]
    groups = []
    for k, (shape, count) in enumerate(zip(shapes, counts)):
        g = {"name": f"g{k}", "shape": shape, "count": count, "rotations": "uniform",
             "centroids": {"box": [-3.0, 3.0]} if centroids is None else {"points": centroids[k]}}
        if order == 2:
            g["velocities"] = {"centroid": {"normal": 0.4}, "angular": {"normal": 0.4}}
        groups.append(g)
    model = {"order": order, "kappa": 1.3, "gamma": 1.2, "kappa_2": 0.7, "L": 1.5}
    if order == 2:
        model["mass"] = 0.5
    return load_scene({"dimension": dim, "seed": 21, "model": model, "groups": groups})


@pytest.mark.parametrize("order,dim", [(1, 2), (2, 2), (2, 3)])
def test_mixed_centroid_force_matches_paper_F_2(order, dim):
    scene = _mixed_scene(order, dim=dim)
    model = scene.model
    assert model.inter_group and not model.centroids_exact
    system = System(model)
    coupling = system.couple(scene.initial.groups)
    xs = [gs.x for gs in scene.initial.groups]
    rates = system.rates(scene.initial, coupling)
    for gi, gs in enumerate(scene.initial.groups):
        expected = np.array([paper_f2_force(xs, gi, i, 1.3, 0.7, 1.5) for i in range(len(gs.x))])
        force = system.centroid_force(gi, gs.x, coupling)
        np.testing.assert_allclose(force, expected, rtol=0, atol=1e-13)
        k_rot, k_x, k_v, k_w = rates[gi]
        if order == 1:
            np.testing.assert_allclose(k_x, expected / model.gamma, rtol=0, atol=1e-13)
        else:
            np.testing.assert_allclose(k_x, gs.v, rtol=0, atol=0)
            np.testing.assert_allclose(
                k_v, (expected - model.gamma * gs.v) / model.mass, rtol=0, atol=1e-12)
        # rotations couple only inside the group, with the group's own N_g
        # (F-2, third/fourth lines)
        mats = rot_matrices(model.rotations, gs.rot)
        scale = 1.3 / (2.0 * len(mats)) if order == 2 else 1.3 / (2.0 * 1.2 * len(mats))
        rate = system.rotation_rate(gi, gs.rot, coupling)
        np.testing.assert_allclose(skew_matrices(model.rotations, rate),
                                   scale * naive_lohe_sum(mats), rtol=0, atol=1e-13)


def test_mixed_force_coincident_centroids_zero_not_nan_F_2():
    # agent 0 of group 0 sits exactly on agent 3 of group 1, agent 1 on agent 0 of group 1
    cents = [[[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]],
             [[1.0, 0.0], [3.0, 3.0], [-2.0, 1.0], [0.0, 0.0]],
             [[5.0, 5.0], [1.0, 0.0], [-1.0, -4.0], [2.0, -2.0], [0.5, 0.5]]]
    scene = _mixed_scene(2, centroids=cents)
    xs = [gs.x for gs in scene.initial.groups]
    assert np.array_equal(xs[0][0], xs[1][3]) and np.array_equal(xs[0][1], xs[1][0])
    assert np.array_equal(xs[0][1], xs[2][1])
    system = System(scene.model)
    coupling = system.couple(scene.initial.groups)
    for gi in range(3):
        force = system.centroid_force(gi, xs[gi], coupling)
        assert np.all(np.isfinite(force))
        expected = np.array([paper_f2_force(xs, gi, i, 1.3, 0.7, 1.5) for i in range(len(xs[gi]))])
        np.testing.assert_allclose(force, expected, rtol=0, atol=1e-13)
    # pair_force alone: a coincident pair contributes exactly zero, other pairs the paper's term
    x = np.array([[0.0, 0.0]])
    y = np.array([[0.0, 0.0], [2.0, 0.0]])
    np.testing.assert_allclose(pair_force(x, y, 0.7, 1.5), [[0.7 / 2 * (2.0 - 1.5), 0.0]],
                               atol=1e-15)
    np.testing.assert_array_equal(pair_force(x, y[:1], 0.7, 1.5), [[0.0, 0.0]])
    # chunked evaluation (one row at a time) gives the same numbers
    rng = np.random.default_rng(3)
    xa, ya = rng.normal(size=(9, 3)), rng.normal(size=(7, 3))
    ya[2] = xa[4]
    np.testing.assert_allclose(pair_force(xa, ya, 0.9, 0.3, chunk=1), pair_force(xa, ya, 0.9, 0.3),
                               rtol=0, atol=1e-15)
    assert np.all(np.isfinite(pair_force(xa, ya, 0.9, 0.3)))


# ---------------------------------------------------------------------------------------------
# exact centroid flow (Proposition 2.1)


def _companion(m, gamma, k):
    return np.array([[0.0, 1.0], [-k / m, -gamma / m]])


FLOW_CASES = [
    (1.0, 1.0, 1.0, 0.1),          # under-damped
    (0.1, 1.0, 1.0, 0.05),         # over-damped
    (1.0, 0.5, 2.0, 0.3),          # under-damped, larger step
    (0.25, 1.0, 1.0, 0.1),         # exactly critical: gamma^2 = 4 m kappa
    (0.25, 1.0, 1.0 + 1e-9, 0.1),  # nearly critical
    (1.0, 0.0, 2.0, 0.1),          # undamped
    (2.0, 3.0, 1.0, 7.0),          # long step
]


@pytest.mark.parametrize("m,gamma,kappa,h", FLOW_CASES)
def test_exact_centroid_flow_equals_expm_prop_2_1(m, gamma, kappa, h):
    p0, pk = CentroidFlow(m, gamma, kappa).propagator(h)
    np.testing.assert_allclose(p0, expm(_companion(m, gamma, 0.0) * h), rtol=1e-13, atol=1e-14)
    np.testing.assert_allclose(pk, expm(_companion(m, gamma, kappa) * h), rtol=1e-13, atol=1e-14)


def test_exact_centroid_flow_first_order_prop_2_1():
    mean, dev = CentroidFlow(0.0, 1.7, 2.3).propagator(0.37)
    assert mean == 1.0
    assert dev == pytest.approx(np.exp(-2.3 * 0.37 / 1.7), rel=1e-15)


@pytest.mark.parametrize("m,gamma,kappa", [(0.3, 0.8, 1.4), (2.0, 0.5, 3.0), (0.0, 1.5, 2.0)])
def test_centroid_flow_advance_equals_full_linear_system_prop_2_1(m, gamma, kappa):
    """advance() against expm of the full 2N x 2N system
    m x'' = -gamma x' + kappa/N sum (x_k - x_i)."""
    rng = np.random.default_rng(5)
    n, d, h = 6, 3, 0.4
    x, v = rng.normal(size=(n, d)), rng.normal(size=(n, d))
    lap = kappa / n * (np.ones((n, n)) - n * np.eye(n))     # (kappa/N) sum_k (x_k - x_i)
    flow = CentroidFlow(m, gamma, kappa)
    if m == 0.0:
        x_new, v_new = flow.advance(x, None, x.mean(axis=0), None, h)
        assert v_new is None
        np.testing.assert_allclose(x_new, expm(lap / gamma * h) @ x, rtol=0, atol=1e-14)
        return
    big = np.block([[np.zeros((n, n)), np.eye(n)], [lap / m, -gamma / m * np.eye(n)]])
    ref = expm(big * h) @ np.vstack([x, v])
    x_new, v_new = flow.advance(x, v, x.mean(axis=0), v.mean(axis=0), h)
    np.testing.assert_allclose(x_new, ref[:n], rtol=0, atol=1e-13)
    np.testing.assert_allclose(v_new, ref[n:], rtol=0, atol=1e-13)


def _stable_closed_form(m, gamma, k, h):
    """exp(h [[0, 1], [-k/m, -gamma/m]]) from the two real roots, computed without cancellation."""
    sq = np.sqrt(gamma * gamma - 4.0 * m * k)
    l1 = -(gamma + sq) / (2.0 * m)                 # fast root
    l2 = -2.0 * k / (gamma + sq)                   # slow root (Vieta: l1 l2 = k / m)
    e1, e2 = np.exp(l1 * h), np.exp(l2 * h)
    dl = l1 - l2
    return np.array([[(l1 * e2 - l2 * e1) / dl, (e1 - e2) / dl],
                     [l1 * l2 * (e2 - e1) / dl, (l1 * e1 - l2 * e2) / dl]])


@pytest.mark.parametrize("m", [1e-8, 1e-11, 1e-14])
def test_exact_centroid_flow_stiff_mass_tends_to_first_order_prop_2_1(m):
    gamma, kappa, h = 2.0, 1.5, 0.01
    p0, pk = CentroidFlow(m, gamma, kappa).propagator(h)
    assert np.all(np.isfinite(p0)) and np.all(np.isfinite(pk))
    ref = _stable_closed_form(m, gamma, kappa, h)
    np.testing.assert_allclose(pk, ref, rtol=1e-12, atol=1e-300)
    # the mean mode (k = 0): x' = v, v' = -(gamma/m) v exactly
    mean_mode = [[1.0, m / gamma * -np.expm1(-gamma * h / m)], [0.0, np.exp(-gamma * h / m)]]
    np.testing.assert_allclose(p0, mean_mode, rtol=1e-12, atol=1e-300)
    if m >= 1e-8:
        # expm agrees too, to its own (lower) accuracy on a stiff matrix
        np.testing.assert_allclose(pk, expm(_companion(m, gamma, kappa) * h), rtol=1e-9, atol=0)
    # the deviation follows the first-order model up to O(m)
    assert abs(pk[0, 0] - np.exp(-kappa * h / gamma)) < 10 * m
    # many steps stay finite and follow the first-order decay
    flow = CentroidFlow(m, gamma, kappa)
    x = np.array([[1.0, -2.0], [-1.0, 2.0]])
    v = np.array([[3.0, 0.0], [-3.0, 0.0]])
    for _ in range(100):
        x, v = flow.advance(x, v, x.mean(axis=0), v.mean(axis=0), h)
    assert np.all(np.isfinite(x)) and np.all(np.isfinite(v))
    # after the O(m/gamma) initial layer the velocity has been absorbed:
    # x(1) = e^{-kappa/gamma} x_slow(0)
    x_slow0 = (np.array([[1.0, -2.0], [-1.0, 2.0]])
               + (m / gamma) * np.array([[3.0, 0.0], [-3.0, 0.0]]))
    np.testing.assert_allclose(x, np.exp(-kappa * 1.0 / gamma) * x_slow0, rtol=1e-6, atol=1e-12)
