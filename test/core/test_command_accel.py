"""The bridge's second-order command: the acceleration of (A-1) at the robot's measured state,
its frames and limits, the damped stop, and the scenes bridge mode refuses (pure, no ROS)."""

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from polymatch_ros.core.errors import ParameterError
from polymatch_ros.core.model import GroupState, State
from polymatch_ros.core.robots.robot_commands import (
    STILL,
    accel_command,
    axial,
    brake_command,
    bridge_model,
    bridge_system,
    is_still,
)
from polymatch_ros.core.scenes.scene import load_scene, resolve_scene_path

SCENE_3D = """\
name: tetrahedra_3d_second_order
description: congruent tetrahedra in R^3, second order (A-1)
dimension: 3
seed: 7
model: {order: 2, mass: 0.7, kappa: 1.5, gamma: 0.9}
integrator: {method: rkmk4, dt: 0.01}
time: {t_end: 1.0, samples: {every: 0.5}}
convergence: {tolerance: 1.0e-6}
groups:
  - {name: tetrahedra, shape: tetrahedron, count: 5, centroids: {box: [-2.0, 2.0]},
     rotations: uniform, velocities: {centroid: {normal: 0.5}, angular: {normal: 0.5}}}
"""


def _scene(tmp_path, which):
    if which == "2d":
        return load_scene(resolve_scene_path("congruent_triangles_second_order"))
    path = tmp_path / "scene.yaml"
    path.write_text(SCENE_3D)
    return load_scene(str(path))


def _direct_a1(model, x, v, mats, w, i):
    """(A-1) written out for agent i: m xbar_i'' = -gamma xbar_i' + kappa/N sum_k (xbar_k -
    xbar_i), m W_i' = -gamma W_i + kappa/(2N) (S O_i^T - O_i S^T), S = sum_k O_k."""
    n, m, g, k = len(x), model.mass, model.gamma, model.kappa
    s = mats.sum(axis=0)
    torque = k / (2 * n) * (s @ mats[i].T - mats[i] @ s.T)
    return (-g * v[i] + k / n * (x - x[i]).sum(axis=0)) / m, (-g * w[i] + torque) / m


def _ensemble(gs):
    """The group arrays a bridged agent assembles from its peers (no velocities needed)."""
    return (SimpleNamespace(x=gs.x, rot=gs.rot, v=None, index=None),)


def _padded(vec):
    out = np.zeros(3)
    out[: len(vec)] = vec
    return out


@pytest.mark.parametrize("which", ["2d", "3d"])
def test_acceleration_command_is_the_second_order_model_a1(tmp_path, which):
    scene = _scene(tmp_path, which)
    model, grp = scene.model, scene.model.rotations
    gs = scene.initial.groups[0]
    mats, skews = grp.to_matrices(gs.rot), grp.algebra_to_skew(gs.w)
    assert np.abs(gs.v).max() > 0.1 and np.abs(skews).max() > 0.1  # the damping term counts
    full = bridge_system(model, None)  # the core's own right-hand side, every agent at once
    rates = full.rates(State(0.0, (GroupState(gs.x, gs.rot, gs.v, gs.w),)),
                       full.couple(_ensemble(gs)))[0]
    for i in range(model.n_agents):
        system = bridge_system(model, [np.array([i])])
        cmd = accel_command(system, 0, i, _ensemble(gs), mats[i], gs.v[i],
                            grp.algebra_take(gs.w, [i]))
        accel, w_dot = _direct_a1(model, gs.x, gs.v, mats, skews, i)
        np.testing.assert_allclose(cmd.linear, _padded(accel), atol=1e-12)
        np.testing.assert_allclose(cmd.linear[: model.dim], rates[2][i], atol=1e-12)
        np.testing.assert_allclose(cmd.angular, axial(w_dot), atol=1e-12)
        np.testing.assert_allclose(grp.algebra_to_skew(rates[3])[i], w_dot, atol=1e-12)
        assert cmd.finite and not cmd.saturated


def test_body_frame_is_r_transpose_and_limits_cut_by_norm(tmp_path):
    scene = _scene(tmp_path, "3d")
    model, grp = scene.model, scene.model.rotations
    gs = scene.initial.groups[0]
    mats = grp.to_matrices(gs.rot)
    system, w0 = bridge_system(model, [np.array([0])]), grp.algebra_take(gs.w, [0])
    world = accel_command(system, 0, 0, _ensemble(gs), mats[0], gs.v[0], w0)
    body = accel_command(system, 0, 0, _ensemble(gs), mats[0], gs.v[0], w0, "body")
    np.testing.assert_allclose(body.linear, mats[0].T @ world.linear, atol=1e-12)
    np.testing.assert_allclose(body.angular, mats[0].T @ world.angular, atol=1e-12)
    limit = 0.5 * min(np.linalg.norm(world.linear), np.linalg.norm(world.angular))
    cut = accel_command(system, 0, 0, _ensemble(gs), mats[0], gs.v[0], w0, "world", limit, limit)
    assert cut.saturated
    np.testing.assert_allclose(np.linalg.norm(cut.linear), limit)
    np.testing.assert_allclose(cut.angular / limit, world.angular / np.linalg.norm(world.angular))


def test_damped_stop_is_a1_without_coupling_and_brings_a_robot_to_rest():
    model = SimpleNamespace(gamma=1.0, mass=0.5)
    skew = np.array([[0.0, -0.4], [0.4, 0.0]])
    v = np.array([0.3, -0.2])
    stop = brake_command(model, v, skew, np.eye(2))
    np.testing.assert_allclose(stop.linear, [-0.6, 0.4, 0.0])
    np.testing.assert_allclose(stop.angular, [0.0, 0.0, -0.8])
    dt, omega = 0.1, skew[1, 0]
    for _ in range(200):  # commanded every tick, held in between: the speed decays
        cmd = brake_command(model, v, skew, np.eye(2))
        v, omega = v + dt * cmd.linear[:2], omega + dt * cmd.angular[2]
        skew = np.array([[0.0, -omega], [omega, 0.0]])
    assert is_still(v, skew) and not is_still([2 * STILL, 0.0], np.zeros((2, 2)))


def test_bridge_refuses_d4_and_undamped_second_order():
    with pytest.raises(ParameterError, match="d = 4"):
        bridge_model(load_scene(resolve_scene_path("simplices_4d")).model)
    model = load_scene(resolve_scene_path("congruent_triangles_second_order")).model
    assert bridge_model(model).centroids == "integrated"
    with pytest.raises(ParameterError, match="gamma > 0"):
        bridge_model(replace(model, gamma=0.0))
