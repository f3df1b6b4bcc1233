"""The adaptive DOP853-Lie run: its step cap and its dense output against independent formulas."""

import numpy as np
import pytest
from core_testlib import make_scene
from scipy.integrate._ivp import dop853_coefficients

from polymatch_ros.core import simulate
from polymatch_ros.core.stepping.adaptive import CAP_FRACTION, AdaptiveLie


def _dop853_stability(z):
    """R(z) = 1 + z b^T (I - z A)^{-1} 1 of scipy's own DOP853 tableau (its 12 stages)."""
    a = dop853_coefficients.A[:dop853_coefficients.N_STAGES, :dop853_coefficients.N_STAGES]
    b, ones = dop853_coefficients.B, np.ones(dop853_coefficients.N_STAGES)
    return np.array([1.0 + zi * b @ np.linalg.solve(np.eye(len(b)) - zi * a, ones)
                     for zi in np.ravel(z)])


def _linear_rates(order, kappa, gamma, mass):
    """The rates of the linearised model near consensus, in closed form: (A-2) relaxes at
    -kappa/gamma; (A-1) at the roots of m s^2 + gamma s + kappa, its velocity damped at
    -gamma/m."""
    if order == 1:
        return np.array([-kappa / gamma])
    return np.append(np.roots([mass, gamma, kappa]), -gamma / mass)


def test_step_cap_is_the_stability_boundary_of_the_dop853_tableau():
    """The cap (over CAP_FRACTION) is the largest h with |R(h s)| <= 1 at every rate s, where R
    is the stability function of scipy's DOP853 tableau and s the closed-form rates."""
    meth = AdaptiveLie(1e-8)
    for order, kappa in ((1, 1.0), (1, 40.0), (2, 3.0)):
        model = make_scene(2, order, kappa=kappa, mass=0.5, velocities={}).model
        cap, cause = meth.step_cap(model)
        assert cause and cap == meth.step_cap(model)[0]            # cached: the same value
        h = cap / CAP_FRACTION                                       # the boundary itself
        rates = _linear_rates(order, kappa, model.gamma, 0.5)
        assert np.all(np.abs(_dop853_stability(h * (1 - 1e-9) * rates)) <= 1.0)
        assert np.any(np.abs(_dop853_stability(h * (1 + 1e-9) * rates)) > 1.0)
    # DOP853's real stability interval reaches about -6 (Hairer & Wanner): kappa/gamma = 1
    boundary = meth.step_cap(make_scene(2, 1, kappa=1.0, velocities={}).model)[0] / CAP_FRACTION
    assert 5.5 < boundary < 6.5, boundary


def test_adaptive_samples_carry_the_exact_centroid_flow_prop_2_1():
    kappa, gamma = 1.3, 0.7
    scene = make_scene(2, 1, count=6, seed=3, kappa=kappa, gamma=gamma, t_end=4.0)
    times = np.linspace(0.0, 4.0, 57)
    traj = simulate(scene, "adaptive", tolerance=1e-6, samples=times, metrics=False)
    x0 = scene.initial.groups[0].x
    mean = x0.mean(axis=0)
    assert np.allclose(traj.times, times)
    assert traj.steps < len(times) - 1                     # several samples inside one step
    for t, st in zip(traj.times, traj.states):
        want = mean + np.exp(-kappa * t / gamma) * (x0 - mean)
        np.testing.assert_allclose(st.groups[0].x, want, rtol=0, atol=1e-13)


def _run_to_end(scene, tol, fast):
    from polymatch_ros.core import State, System
    run = AdaptiveLie(tol).solver(System(scene.model), State(0.0, scene.initial.groups),
                                  scene.t_end, samples=np.linspace(0.0, scene.t_end, 9))
    if not fast:
        run.fast = None                                   # the general path: State objects
    out = []
    while run.status == "running":
        out += run.step()
    return run, out


@pytest.mark.parametrize("dim", [2, 3, 4])
def test_rotations_only_stages_equal_the_general_path_bitwise(dim):
    scene = make_scene(dim, 1, count=5, seed=dim, t_end=3.0)
    fast, fast_out = _run_to_end(scene, 1e-9, True)
    assert fast.fast is not None                          # the scene takes the fast path
    slow, slow_out = _run_to_end(scene, 1e-9, False)
    assert (fast.nsteps, fast.nfev) == (slow.nsteps, slow.nfev)
    for a, b in zip(fast_out + [fast.state], slow_out + [slow.state]):
        assert a.t == b.t
        assert np.array_equal(a.groups[0].rot, b.groups[0].rot)
        assert np.array_equal(a.groups[0].x, b.groups[0].x)
