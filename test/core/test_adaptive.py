"""The adaptive DOP853-Lie run: its step cap and its dense output against independent formulas."""

import numpy as np
import pytest
from core_testlib import make_scene

from polymatch_ros.core import simulate, stability
from polymatch_ros.core.adaptive import CAP_FRACTION, AdaptiveLie
from polymatch_ros.core.rk import rk_stability


def test_step_cap_is_the_stability_boundary_of_the_dop853_tableau():
    meth = AdaptiveLie(1e-8)
    for order, kappa in ((1, 1.0), (1, 40.0), (2, 3.0)):
        model = make_scene(2, order, kappa=kappa, mass=0.5, velocities={}).model
        cap, cause = meth.step_cap(model)
        assert cause and cap == meth.step_cap(model)[0]            # cached: the same value
        h = cap / CAP_FRACTION                                       # the boundary itself
        for _, mat, _ in stability.test_matrices(model):
            lam = np.linalg.eigvals(np.atleast_2d(mat))
            assert np.all(np.abs(rk_stability(meth.A, meth.B, h * (1 - 1e-9) * lam)) <= 1.0)
        assert any(np.any(np.abs(rk_stability(meth.A, meth.B, h * (1 + 1e-9) * lam)) > 1.0)
                   for _, mat, _ in stability.test_matrices(model)
                   for lam in [np.linalg.eigvals(np.atleast_2d(mat))])


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
