"""The bridge's command is the first-order model (A-2): the twist a bridged agent sends its
robot is (A-2) written out, saturated along its own direction, and ideal robots it drives follow
the centralised run."""

import math
from types import SimpleNamespace

import numpy as np
import pytest
from ros_harness import scene_path
from scipy.spatial.transform import Rotation

from polymatch_ros.core.errors import ParameterError
from polymatch_ros.core.metrics import ensemble_metrics
from polymatch_ros.core.model import GroupState, State
from polymatch_ros.core.robots.robot_commands import (
    bridge_model,
    bridge_system,
    command_from_ensemble,
    noise_floor,
    saturate,
    twist_command,
)
from polymatch_ros.core.scenes.scene import load_scene
from polymatch_ros.core.stepping.simulate import simulate
from polymatch_ros.ros.nodes.robot import SimulatedRobot

SCENE_3D = """\
name: tetrahedra_3d
description: congruent tetrahedra in R^3, first order (A-2)
dimension: 3
seed: 5
model: {order: 1, kappa: 1.5, gamma: 1.0}
integrator: {method: rkmk4, dt: 0.01}
time: {t_end: 1.0, samples: {every: 0.5}}
convergence: {tolerance: 1.0e-6}
groups:
  - {name: tetrahedra, shape: tetrahedron, count: 5, centroids: {box: [-2.0, 2.0]},
     rotations: uniform}
"""


def _scene(tmp_path, text, name="scene.yaml"):
    path = tmp_path / name
    path.write_text(text)
    return str(path)


def _arrays(scene):
    """The initial ensemble as group arrays (what a bridged agent assembles from its peers)."""
    return tuple(SimpleNamespace(x=gs.x, rot=gs.rot, v=None, index=None)
                 for gs in scene.initial.groups)


def _direct_a2(model, x, mats, i):
    """(A-2) written out: xbar_i' = kappa/(gamma N) sum_k (xbar_k - xbar_i),
    W_i = kappa/(2 gamma N) (S O_i^T - O_i S^T), S = sum_k O_k."""
    n, gain = len(x), model.kappa / model.gamma
    s = mats.sum(axis=0)
    w = gain / (2 * n) * (s @ mats[i].T - mats[i] @ s.T)
    return gain / n * (x - x[i]).sum(axis=0), w


@pytest.mark.parametrize("which", ["2d", "3d"])
def test_command_is_the_first_order_model_a2(tmp_path, which):
    path = scene_path("congruent_triangles") if which == "2d" else _scene(tmp_path, SCENE_3D)
    scene = load_scene(path)
    model, grp = scene.model, scene.model.rotations
    gs = scene.initial.groups[0]
    mats = grp.to_matrices(gs.rot)
    central = bridge_system(model, None).rates(  # the core's own right-hand side
        State(0.0, (GroupState(gs.x, gs.rot),)), bridge_system(model, None).couple(_arrays(scene))
    )[0]
    central_w = grp.algebra_to_skew(central[0])
    for i in range(model.n_agents):
        system = bridge_system(model, [np.array([i])])
        twist = command_from_ensemble(system, 0, i, _arrays(scene), mats[i])
        velocity, w = _direct_a2(model, gs.x, mats, i)
        lin = np.zeros(3)
        lin[: model.dim] = velocity
        np.testing.assert_allclose(twist.linear, lin, atol=1e-12)
        np.testing.assert_allclose(twist.linear[: model.dim], central[1][i], atol=1e-12)
        axial = [w[2, 1], w[0, 2], w[1, 0]] if model.dim == 3 else [0.0, 0.0, w[1, 0]]
        np.testing.assert_allclose(twist.angular, axial, atol=1e-12)
        np.testing.assert_allclose(central_w[i], w, atol=1e-12)
        assert not twist.saturated


def test_saturation_keeps_the_direction_and_body_frame_is_r_transpose():
    rot = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # 90 deg about z
    skew = np.array([[0.0, -0.3, 0.2], [0.3, 0.0, -0.1], [-0.2, 0.1, 0.0]])
    world = twist_command(np.array([3.0, 4.0, 0.0]), skew, rot)
    np.testing.assert_allclose(world.angular, [0.1, 0.2, 0.3])
    body = twist_command(np.array([3.0, 4.0, 0.0]), skew, rot, frame="body")
    np.testing.assert_allclose(body.linear, rot.T @ world.linear)
    np.testing.assert_allclose(body.angular, rot.T @ world.angular)
    cut = twist_command(np.array([3.0, 4.0, 0.0]), skew, rot, max_linear=1.0, max_angular=0.1)
    assert cut.saturated
    np.testing.assert_allclose(cut.linear, [0.6, 0.8, 0.0])
    np.testing.assert_allclose(np.linalg.norm(cut.angular), 0.1)
    np.testing.assert_allclose(cut.angular / 0.1, world.angular / np.linalg.norm(world.angular))
    vec, was_cut = saturate(np.array([0.3, 0.4]), 1.0)
    assert not was_cut and np.allclose(vec, [0.3, 0.4])
    with pytest.raises(ParameterError, match="frame"):
        twist_command(np.zeros(2), np.zeros((2, 2)), np.eye(2), frame="robot")


def test_bridge_refuses_d4():
    with pytest.raises(ParameterError, match="d = 4"):
        bridge_model(load_scene(scene_path("simplices_4d")).model)


@pytest.mark.parametrize("frame", ["world", "body"])
def test_ideal_robots_driven_by_the_command_follow_the_model(tmp_path, frame):
    """Robots without lag or noise, commanded every dt, reproduce (A-2) to O(dt)."""
    scene = load_scene(_scene(tmp_path, SCENE_3D))
    model, grp = scene.model, scene.model.rotations
    gs = scene.initial.groups[0]
    robots = [SimulatedRobot(gs.x[i], m, False, 0.0, math.inf, math.inf)
              for i, m in enumerate(grp.to_matrices(gs.rot))]
    dt = 1e-3
    for _ in range(int(round(scene.t_end / dt))):
        x = np.array([r.p for r in robots])
        mats = np.array([r.rot.as_matrix() for r in robots])
        arrays = (SimpleNamespace(x=x, rot=grp.from_matrices(mats), v=None, index=None),)
        twists = [command_from_ensemble(bridge_system(model, [np.array([i])]), 0, i, arrays,
                                        mats[i], frame) for i in range(len(robots))]
        for r, tw in zip(robots, twists):
            r.step(dt, tw.linear, tw.angular, frame)
    final = State(scene.t_end, (GroupState(np.array([r.p for r in robots]), grp.from_matrices(
        np.array([r.rot.as_matrix() for r in robots]))),))
    ref = simulate(scene).states[-1]
    np.testing.assert_allclose(final.groups[0].x, ref.groups[0].x, atol=5e-3)
    np.testing.assert_allclose(grp.to_matrices(final.groups[0].rot),
                               grp.to_matrices(ref.groups[0].rot), atol=5e-3)
    d0 = ensemble_metrics(model, scene.initial).diameter
    assert ensemble_metrics(model, final).diameter < 0.8 * d0


def _noise_diameters(dim, sigma_p, sigma_theta, reference, agents=8, trials=2000, seed=0):
    """The matching diameter of ``agents`` robots all at the same true pose, each measured as
    the robots measure (Gaussian noise: sigma_p per position coordinate, sigma_theta per rotation
    vector component, about z alone in the plane), in ``trials`` draws: what noise alone makes."""
    rng = np.random.default_rng(seed)
    turn = rng.normal(0.0, sigma_theta, (trials * agents, 3))
    if dim == 2:
        turn[:, :2] = 0.0
    mats = Rotation.from_rotvec(turn).as_matrix()[:, :dim, :dim].reshape(trials, agents, dim,
                                                                           dim)
    shift = rng.normal(0.0, sigma_p, (trials, agents, 1, dim))
    verts = shift + np.einsum("tnij,aj->tnai", mats, reference)
    gaps = np.linalg.norm(verts[:, :, None] - verts[:, None], axis=-1)      # (t, n, n, a)
    return gaps.max(axis=(1, 2, 3))


@pytest.mark.parametrize("dim,sigma_p,sigma_theta", [(2, 0.002, 0.002), (2, 0.01, 0.0),
                                                     (3, 0.0, 0.005), (3, 0.005, 0.005)])
def test_noise_floor_covers_what_measurement_noise_alone_makes(dim, sigma_p, sigma_theta):
    """Eight robots at one pose, measured with noise (sampled here): their matching diameter
    stays below ``noise_floor`` in 99.9% of draws, and the floor is not idle (within 20 times the
    median); no noise, no floor."""
    reference = (np.array([[1.0, 0.0], [-0.5, 0.8660254037844386], [-0.5, -0.8660254037844386]])
                 if dim == 2 else
                 np.array([[1.0, 1.0, 1.0], [1.0, -1.0, -1.0], [-1.0, 1.0, -1.0],
                           [-1.0, -1.0, 1.0]]) / math.sqrt(3.0))
    radius = float(np.linalg.norm(reference, axis=1).max())
    floor = noise_floor(sigma_p, sigma_theta, radius, dim)
    diameters = _noise_diameters(dim, sigma_p, sigma_theta, reference)
    assert np.quantile(diameters, 0.999) < floor, (np.quantile(diameters, 0.999), floor)
    assert floor < 20 * np.median(diameters), (np.median(diameters), floor)
    assert noise_floor(0.0, 0.0, radius, dim) == 0.0


def test_robot_applies_a_command_one_timeout_then_brakes_within_the_step():
    """The simulated robot's watchdog (what the safety filter's horizon assumes): over a step of
    0.2 s whose command came 0.05 s (``cmd_timeout``) before it began to expire, the velocity
    follows the command for 0.05 s and then decays to zero with the lag, in closed form
    u (1 - e^{-0.05/lag}) e^{-0.15/lag}; the position moves by each part's velocity times its
    duration (the robot's explicit update), written out here."""
    from polymatch_ros.ros.config.configs import RobotConfig
    from polymatch_ros.ros.nodes.robot import RobotNode

    lag, u = 0.1, np.array([0.8, -0.4, 0.0])
    node = RobotNode.__new__(RobotNode)
    node.robot = SimulatedRobot([0.0, 0.0], np.eye(2), True, lag, math.inf, math.inf)
    node.config = RobotConfig(cmd_timeout=0.05, command_frame="world", drive="holonomic")
    node.second_order = False
    node.command = (u, np.zeros(3), 10.0)         # heard at 10.0 s (monotonic)
    node._advance(0.2, 10.2)
    held = u * (1.0 - math.exp(-0.05 / lag))
    np.testing.assert_allclose(node.robot.v, held * math.exp(-0.15 / lag), atol=1e-15)
    np.testing.assert_allclose(node.robot.p, held * 0.05 + held * math.exp(-0.15 / lag) * 0.15,
                               atol=1e-15)
    node._advance(0.05, 10.25)                    # a stale command moves nothing more in
    np.testing.assert_allclose(node.robot.v, held * math.exp(-0.2 / lag), atol=1e-15)
