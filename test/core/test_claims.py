"""What the paper promises, measured on simulated trajectories.

Prop. 2.1     centroid-diameter decay rates (over-damped, under-damped, first order)
Prop. 2.2 i   the energy E never increases; E(0) - E(t) = (2 gamma/N) int sum |O_i'|^2 (and is
              conserved, without drift, by the symplectic splitting when gamma = 0)
Prop. 2.2 ii  first-order rotation diameter D(t) <= D0 / ((1 - D0) e^{kappa t} + D0) for D0 < 1
Thm. 4.1/4.2  complete vertex matching max_{i,j,a} |x^i_a - x^j_a| -> 0
"""

from pathlib import Path

import numpy as np
import pytest
from core_testlib import (
    brute_diameter,
    brute_matching_diameter,
    brute_rotation_diameter,
    make_scene,
    rot_matrices,
    rotation_energy,
    skew_matrices,
)
from scipy.integrate import simpson

from polymatch_ros.core import METHODS, System, drive, load_scene, point_set_diameter, simulate

CONFIG = Path(__file__).resolve().parents[2] / "config"


# ---------------------------------------------------------------------------------------------
# Proposition 2.1


def _centroid_diameters(traj):
    """D(t) computed here by brute force from the states, checked against the core's metric."""
    d = np.array([brute_diameter(st.groups[0].x) for st in traj.states])
    core = np.array([m.groups[0].centroid_diameter for m in traj.metrics])
    np.testing.assert_allclose(core, d, rtol=1e-12, atol=1e-300)
    return np.array(traj.times), d


def test_centroid_decay_rate_overdamped_prop_2_1():
    m, gamma, kappa = 0.1, 1.0, 1.0
    assert gamma ** 2 - 4 * m * kappa > 0
    rate = (-gamma + np.sqrt(gamma ** 2 - 4 * m * kappa)) / (2 * m)
    scene = make_scene(3, 2, count=6, seed=31, mass=m, gamma=gamma, kappa=kappa, t_end=10.0,
                       samples=[4.0, 10.0], velocities={"centroid": {"normal": 0.5}})
    t, d = _centroid_diameters(simulate(scene, "lie_euler", 0.05))
    i4, i10 = list(np.round(t, 9)).index(4.0), list(np.round(t, 9)).index(10.0)
    measured = (np.log(d[i10]) - np.log(d[i4])) / (t[i10] - t[i4])
    assert d[i10] < 1e-3 * d[0]
    assert measured == pytest.approx(rate, rel=0.01)


def test_centroid_decay_rate_underdamped_envelope_prop_2_1():
    m, gamma, kappa = 1.0, 0.5, 2.0
    assert gamma ** 2 - 4 * m * kappa < 0
    rate = -gamma / (2 * m)
    # zero initial velocities: every pair oscillates with the same phase, so successive local
    # maxima of D(t) are exactly one half-period apart and lie on the envelope's exponential
    scene = make_scene(2, 2, count=6, seed=32, mass=m, gamma=gamma, kappa=kappa, t_end=24.0,
                       samples={"every": 0.02})
    t, d = _centroid_diameters(simulate(scene, "lie_euler", 0.02))
    logd = np.log(d)
    peaks = [k for k in range(1, len(d) - 1) if logd[k - 1] < logd[k] > logd[k + 1]]
    assert len(peaks) >= 10                               # it does oscillate
    half_period = np.pi / np.sqrt(4 * m * kappa - gamma ** 2) * 2 * m
    assert np.diff(t[peaks]) == pytest.approx(half_period, abs=0.021)
    slope = np.polyfit(t[peaks], logd[peaks], 1)[0]
    assert slope == pytest.approx(rate, rel=0.01)


def test_centroid_decay_rate_first_order_prop_2_1():
    gamma, kappa = 2.0, 1.5
    scene = make_scene(3, 1, count=6, seed=33, gamma=gamma,
                       kappa=kappa, t_end=8.0, samples=[1.0, 8.0])
    t, d = _centroid_diameters(simulate(scene, "lie_euler", 0.05))
    measured = (np.log(d[-1]) - np.log(d[1])) / (t[-1] - t[1])
    assert measured == pytest.approx(-kappa / gamma, rel=0.01)


@pytest.mark.parametrize("order", [1, 2])
def test_centroid_mean_mode_prop_2_1(order):
    """Summing (B-1) over i: m xbar'' = -gamma xbar' for the mean, i.e. the centre of mass moves
    as xbar(t) = xbar(0) + (m/gamma)(1 - e^{-gamma t/m}) vbar(0) (constant for the first-order
    model)."""
    m, gamma = 0.4, 1.3
    scene = make_scene(3, order, count=6, seed=34, mass=m, gamma=gamma, kappa=2.0, t_end=3.0,
                       samples={"every": 0.5}, velocities={"centroid": {"normal": 1.0}})
    traj = simulate(scene, "lie_euler", 0.05)
    x0 = scene.initial.groups[0].x.mean(axis=0)
    v0 = None if order == 1 else scene.initial.groups[0].v.mean(axis=0)
    assert order == 1 or np.linalg.norm(v0) > 0.1
    for t, st in zip(traj.times, traj.states):
        expected = x0 if order == 1 else x0 + (m / gamma) * (-np.expm1(-gamma * t / m)) * v0
        np.testing.assert_allclose(st.groups[0].x.mean(axis=0), expected, rtol=0, atol=1e-13)
        if order == 2:
            np.testing.assert_allclose(st.groups[0].v.mean(axis=0), np.exp(-gamma * t / m) * v0,
                                       rtol=0, atol=1e-13)
    assert brute_diameter(traj.final.groups[0].x) < 0.2 * brute_diameter(scene.initial.groups[0].x)


# ---------------------------------------------------------------------------------------------
# Proposition 2.2 (ii)


@pytest.mark.parametrize("dim,seed", [(2, 2), (3, 1), (3, 3), (4, 1)])
def test_first_order_rotation_bound_prop_2_2_ii(dim, seed):
    kappa = 1.5                                           # gamma = 1 as in the proposition
    scene = make_scene(dim, 1, count=6, seed=seed, kappa=kappa, gamma=1.0,
                       rotations={"within": 0.3}, t_end=8.0, samples={"every": 0.05})
    # a step a sample; rkmk4 at dt = 0.05 is within 2e-6 of dt = 0.01 relative to the bound,
    # and the bound is met with >= 3% to spare at every t > 0
    traj = simulate(scene, "rkmk4", 0.05)
    t = np.array(traj.times)
    d = np.array([brute_rotation_diameter(rot_matrices(scene.model.rotations, st.groups[0].rot))
                  for st in traj.states])
    core = np.array([m.groups[0].rotation_diameter for m in traj.metrics])
    np.testing.assert_allclose(core, d, rtol=1e-12, atol=1e-15)
    d0 = d[0]
    assert 0.2 < d0 < 1.0                           # the proposition's hypothesis, not vacuous
    bound = d0 / ((1 - d0) * np.exp(kappa * t) + d0)
    assert np.all(d <= bound * (1 + 1e-9))
    assert d[-1] < 1e-3 * d0                              # and it really decays


# ---------------------------------------------------------------------------------------------
# Proposition 2.2 (i)


def _sum_sq_rotation_rates(rep, groups):
    """sum_i |O_i'|_F^2 = sum_i |W_i O_i|_F^2 of each group state, the hats of all of them built
    in one call: these algebra layouts ((N,), (3, N), so(4) parts (6, N)) put the agent last."""
    mats = np.stack([rot_matrices(rep, gs.rot) for gs in groups])          # (S, N, d, d)
    assert all(np.shape(gs.w)[-1] == mats.shape[1] for gs in groups)
    hats = skew_matrices(rep, np.concatenate([gs.w for gs in groups], axis=-1))
    odot = np.einsum("snij,snjk->snik", hats.reshape(mats.shape), mats)
    return np.sum(odot * odot, axis=(1, 2, 3))


@pytest.mark.parametrize("dim,rep", [(2, "angle"), (3, "so3"), (4, "matrix")])
def test_energy_nonincreasing_and_dissipation_identity_prop_2_2_i(dim, rep):
    m, gamma, kappa, n = 0.5, 0.5, 1.0, 5
    scene = make_scene(dim, 2, count=n, seed=41, mass=m, gamma=gamma, kappa=kappa, t_end=8.0,
                       samples={"every": 0.02}, velocities={"angular": {"normal": 1.0}})
    assert scene.model.rotations.name == rep
    # a step a sample: E is checked after every step.  The identity's residual is Simpson's on
    # the samples, 0.02 apart: <= 2.2e-8 at dt = 0.02 (1.6e-8 at dt = 0.01), against 1e-7
    traj = simulate(scene, "rkmk4", 0.02)
    e = np.array([rotation_energy(scene.model, st.groups[0]) for st in traj.states])
    core = np.array([met.groups[0].energy for met in traj.metrics])
    np.testing.assert_allclose(core, e, rtol=1e-12, atol=0)
    assert np.all(np.diff(e) <= 1e-12 * e[0])             # never increases
    assert e[-1] < 0.5 * e[0]
    # E(0) - E(t) = (2 gamma / N) int_0^t sum_i |O_i'|_F^2 ds   (proof of Prop. 2.2 i)
    kin = _sum_sq_rotation_rates(scene.model.rotations, [st.groups[0] for st in traj.states])
    dissipated = 2 * gamma / n * simpson(kin, x=np.array(traj.times))
    assert e[0] - e[-1] == pytest.approx(dissipated, rel=1e-7)


def _energy_run(method, dt, t_end=100.0, every=0.1):
    scene = make_scene(3, 2, count=3, seed=2, mass=0.5, gamma=0.0, kappa=1.0, t_end=t_end,
                       velocities={"angular": {"normal": 1.0}})
    system = System(scene.model)
    meth = METHODS[method]
    state = scene.initial
    stride = int(round(every / dt))
    energies = [rotation_energy(scene.model, state.groups[0])]
    for k in range(int(round(t_end / dt))):
        state = drive(meth, system, state, dt)
        if (k + 1) % stride == 0:
            energies.append(rotation_energy(scene.model, state.groups[0]))
    e = np.array(energies)
    dev = np.abs(e - e[0]) / e[0]
    early = dev[: len(dev) // 8].max()                    # max deviation over [0, T/8]
    return dev.max(), early


def test_energy_conserved_without_drift_gamma_0_lie_verlet_prop_2_2_i():
    """Over t = 100 at dt = 0.1 and 0.05 (measured: deviations 1.3e-3 and 2.9e-4, ratio 4.6;
    max over [0, T] / max over [0, T/8]: 1.12 and 1.00; lie_heun at dt = 0.1: 7.6)."""
    dev1, early1 = _energy_run("lie_verlet", 0.1)
    dev2, early2 = _energy_run("lie_verlet", 0.05)
    assert dev2 < 1e-3
    # O(dt^2) oscillation (O(dt) would give 2)
    assert dev1 / dev2 > 2.5
    assert dev1 < 3 * early1 and dev2 < 3 * early2         # bounded: no growth over 8x the time
    # the criterion does detect drift: a non-symplectic 2nd-order method fails it
    dev_h, early_h = _energy_run("lie_heun", 0.1)
    assert dev_h > 3 * early_h


# ---------------------------------------------------------------------------------------------
# Theorems 4.1 and 4.2


THEOREM_SCENES = [
    ("congruent_triangles.yaml", 1),                  # Theorem 4.2 (first order; D0 >= 1 here)
    ("congruent_triangles_second_order.yaml", 2),     # Theorem 4.1 (second order)
]


@pytest.mark.parametrize("name,order", THEOREM_SCENES)
def test_complete_vertex_matching_config_theorems_4_1_4_2(name, order):
    scene = load_scene(CONFIG / name)
    assert scene.model.order == order and scene.model.groups[0].scales is None
    traj = simulate(scene)
    assert traj.final.t == pytest.approx(scene.t_end)
    d0 = brute_matching_diameter(scene.model, scene.initial, 0)
    dend = brute_matching_diameter(scene.model, traj.final, 0)
    assert d0 > 1.0
    assert dend < 1e-6
    assert traj.diameters[-1] == pytest.approx(dend, abs=1e-12)
    assert traj.metrics[0].diameter == pytest.approx(d0, rel=1e-12)
    # and the components the proofs use: centroids and rotations both reach consensus
    assert brute_diameter(traj.final.groups[0].x) < 1e-6
    final = rot_matrices(scene.model.rotations, traj.final.groups[0].rot)
    assert brute_rotation_diameter(final) < 1e-6


@pytest.mark.parametrize("order,dim", [(1, 3), (2, 3), (1, 4)])
def test_complete_vertex_matching_inline_theorems_4_1_4_2(order, dim):
    """Theorem 4.2 under its own hypothesis D0 < 1, and Theorem 4.1 for tetrahedra in R^3."""
    rotations = {"within": 0.3} if order == 1 else "uniform"
    velocities = {"centroid": {"normal": 0.5}, "angular": {"normal": 0.5}}
    # measured at t_end: 8.5e-9 and 9.8e-9 (first order, R^3 and R^4, t = 20), 4.8e-9 (second)
    t_end = 20.0 if order == 1 else 25.0
    scene = make_scene(dim, order, count=6, seed=8, rotations=rotations, mass=0.5,
                       velocities=velocities, t_end=t_end, samples={"every": 5.0})
    if order == 1:
        initial = rot_matrices(scene.model.rotations, scene.initial.groups[0].rot)
        assert brute_rotation_diameter(initial) < 1
    traj = simulate(scene, "rkmk4", 0.05)
    dend = brute_matching_diameter(scene.model, traj.final, 0)
    assert dend < 1e-6
    assert traj.diameters[-1] == pytest.approx(dend, abs=1e-12)


def test_point_set_diameter_is_exact_theorems_4_1_4_2():
    """The diameter every claim is measured with equals the brute-force maximum (incl. blocked
    search)."""
    rng = np.random.default_rng(9)
    for n, k in [(2, 3), (7, 2), (300, 3), (700, 9), (600, 2)]:
        pts = rng.normal(size=(n, k)) * rng.uniform(0.1, 10.0, size=k) + 1e6
        assert point_set_diameter(pts) == pytest.approx(brute_diameter(pts), rel=1e-9)
    # clustered points with one far outlier pair, and points on a sphere (no pruning possible)
    sphere = rng.normal(size=(500, 3))
    sphere /= np.linalg.norm(sphere, axis=1)[:, None]
    assert point_set_diameter(sphere) == pytest.approx(brute_diameter(sphere), rel=1e-12)
    assert point_set_diameter(np.zeros((5, 2))) == 0.0
