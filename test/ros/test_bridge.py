"""Robots in the loop: the bridge's command is the first-order model (A-2) (pure tests), and
simulated robots driven by bridged agents match, stop when their pose goes stale, and take
gains changed while running (multi-process tests)."""

import math
import os
import re
import textwrap
import time
from types import SimpleNamespace

import numpy as np
import pytest
import yaml
from ros_harness import PY, REPO, needs_ros, scene_path

from polymatch_ros.core.command import (
    ZERO,
    bridge_model,
    bridge_system,
    command_from_ensemble,
    noise_floor,
    saturate,
    twist_command,
)
from polymatch_ros.core.errors import ParameterError
from polymatch_ros.core.metrics import ensemble_metrics
from polymatch_ros.core.model import GroupState, State
from polymatch_ros.core.scene import load_scene
from polymatch_ros.core.simulate import simulate
from polymatch_ros.ros.nodes.bridge import BridgeAgent
from polymatch_ros.ros.nodes.params import AGENT, check
from polymatch_ros.ros.nodes.robot import SimulatedRobot
from polymatch_ros.ros.nodes.runtime_params import validate

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

# four triangles close to each other: robots reach the noise floor in a few seconds
PROBE = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "support",
                     "service_probe.py")
SCENE_ROBOTS = """\
name: robot_triangles
description: four congruent triangles driven as robots (A-2)
dimension: 2
seed: 2
model: {{order: 1, kappa: 2.0, gamma: 1.0}}
integrator: {{method: rkmk4, dt: 0.05}}
time: {{t_end: {t_end}, samples: {{every: 0.5}}}}
convergence: {{tolerance: 1.0e-6}}
groups:
  - {{name: triangles, shape: triangle, count: {count}, centroids: {{box: [-1.0, 1.0]}},
     rotations: {{within: 1.5}}}}
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


def test_second_order_hold_brakes_a_moving_robot_then_sends_one_zero():
    """Pause (or a non-finite command): the damped stop each tick while the measured velocity is
    fresh and above STILL, then one zero and quiet; a stale pose: one zero at once."""
    model = bridge_model(load_scene(scene_path("congruent_triangles_second_order")).model)
    grp, sent = model.rotations, []
    agent = object.__new__(BridgeAgent)  # the hold logic alone, without a node
    agent.model, agent.grp, agent.zero_sent, agent.holding = model, grp, False, ""
    agent.params = check(AGENT, {"scene": "x", "mode": "bridge", "pose_type": "odometry"})
    agent.cmd_pub = SimpleNamespace(publish=sent.append)
    agent._message = lambda command: command
    agent.log = SimpleNamespace(warning=lambda text: None)

    def measure(v, omega, heard):
        w = grp.algebra_from_skew(np.array([[[0.0, -omega], [omega, 0.0]]]))
        agent.measured = SimpleNamespace(x=np.zeros(2), rot=grp.from_matrices(np.eye(2)[None]),
                                         v=np.array(v), w=w, heard=heard)

    measure([0.4, 0.0], 0.5, time.monotonic())
    agent._hold("paused", brake=True)
    rate = model.gamma / model.mass
    np.testing.assert_allclose(sent[-1].linear, [-rate * 0.4, 0.0, 0.0])
    np.testing.assert_allclose(sent[-1].angular, [0.0, 0.0, -rate * 0.5])
    measure([0.0, 1e-4], 0.0, time.monotonic())  # at rest: one zero, then quiet
    agent._hold("paused", brake=True)
    agent._hold("paused", brake=True)
    assert len(sent) == 2 and sent[-1] is ZERO and agent.holding == "paused"
    measure([0.4, 0.0], 0.5, time.monotonic() - 10.0)  # stale: no velocity to brake on
    agent.zero_sent = False
    agent._hold("measured pose older than 0.5 s", brake=True)
    assert len(sent) == 3 and sent[-1] is ZERO


def test_noise_floor_grows_with_the_noise():
    assert noise_floor(0.0, 0.0, 1.0, 2) == 0.0
    assert noise_floor(0.01, 0.0, 1.0, 2) < noise_floor(0.02, 0.0, 1.0, 2)
    assert noise_floor(0.0, 0.01, 1.0, 3) < noise_floor(0.0, 0.01, 2.0, 3)


PARAMS_FILE = os.path.join(REPO, "config", "params", "bridge_agent.yaml")


def test_shipped_params_file_is_a_valid_bridge_agent_configuration():
    with open(PARAMS_FILE) as fh:
        values = yaml.safe_load(fh)["/**"]["ros__parameters"]
    assert values["mode"] == "bridge" and set(values) <= {p.name for p in AGENT}
    checked = check(AGENT, dict(values, scene="congruent_triangles"))
    assert checked["max_linear_speed"] == 0.5


def test_runtime_parameters_are_checked_against_their_ranges():
    def change(name, value):
        return SimpleNamespace(name=name, value=value)

    assert validate([change("kappa", 2.5), change("rate", 20)]) == (
        {"kappa": 2.5, "rate": 20.0}, None)
    accepted, reason = validate([change("kappa", -1.0)])
    assert accepted is None and "out of range" in reason
    accepted, reason = validate([change("max_linear_speed", "fast")])
    assert accepted is None and "expected a number" in reason
    accepted, reason = validate([change("scene", "other.yaml")])
    assert accepted is None and "read-only" in reason


# -- robots in the loop (multi-process) ----------------------------------------------

SET_PARAMETER = textwrap.dedent("""\
    import sys
    import rclpy
    from rcl_interfaces.srv import SetParameters
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    rclpy.init()
    node = Node("param_setter")
    client = node.create_client(SetParameters, sys.argv[1] + "/set_parameters")
    assert client.wait_for_service(timeout_sec=20.0), "no parameter service"
    request = SetParameters.Request()
    request.parameters = [Parameter(sys.argv[2], value=eval(sys.argv[3])).to_parameter_msg()]
    future = client.call_async(request)
    rclpy.spin_until_future_complete(node, future, timeout_sec=20.0)
    result = future.result().results[0]
    print("RESULT", result.successful, result.reason, flush=True)
""")


def _set_parameter(ros, node, name, value):
    """(successful, reason) of a SetParameters call, as `ros2 param set` makes it."""
    proc = ros.start([PY, "-c", SET_PARAMETER, node, name, repr(value)], timeout=40)
    assert ros.wait(proc, 45) == 0, ros.output(proc)
    found = re.search(r"^RESULT (True|False) ?(.*)$", ros.output(proc), re.M)
    assert found, ros.output(proc)
    return found.group(1) == "True", found.group(2)


def _twists(text):
    """Every Twist `polymatch echo` printed: (linear xyz, angular xyz) rows."""
    out = []
    for block in text.split("---"):
        values = re.findall(r"^\s+[xyz]: (\S+)$", block, re.M)
        if len(values) == 6:
            out.append([float(v) for v in values])
    return np.array(out).reshape(-1, 6)


def _probe(ros, *actions):
    """What ``test/support/service_probe.py`` printed (service calls, as ``ros2 service call``)."""
    proc = ros.start([PY, PROBE, *actions], timeout=70, name="probe")
    assert ros.wait(proc, 80) == 0, ros.output(proc)
    return ros.output(proc)


def _wait(predicate, timeout):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.2)
    return predicate()


def _robot(ros, scene, agent, **params):
    argv = [PY, "-m", "polymatch_ros.ros.nodes.robot", "--ros-args",
            "-r", f"__ns:=/polymatch/robot_{agent}", "-r", "__node:=robot",
            "-p", f"scene:={scene}", "-p", f"agent:={agent}"]
    argv += [a for k, v in params.items() for a in ("-p", f"{k}:={v!r}")]
    return ros.start(argv, timeout=100, name=f"robot {agent}")


@needs_ros
def test_runtime_gain_pause_service_killed_and_restarted_robot(ros, tmp_path):
    """A gain set at runtime, a pause (one zero command, then quiet), a killed robot (one zero
    command, then quiet) and the same robot restarted (driven again)."""
    scene = _scene(tmp_path, SCENE_ROBOTS.format(t_end=80.0, count=2))
    robots = [_robot(ros, scene, a, position_noise=0.0005) for a in range(2)]
    agents = []
    for a in range(2):
        argv = [PY, "-m", "polymatch_ros.ros.nodes.agent", "--ros-args",
                "--params-file", PARAMS_FILE, "-p", f"scene:={scene}", "-p", f"agent:={a}",
                "-p", "start:=now", "-r", f"measured_pose:=robot_{a}/measured_pose",
                "-r", f"cmd_vel:=robot_{a}/cmd_vel", "-r", f"__node:=agent_{a}"]
        agents.append(ros.start(argv, timeout=100, name=f"agent {a}"))
    echo = ros.start([PY, "-m", "polymatch_ros.cli", "echo", "/polymatch/robot_0/cmd_vel",
                      "--timeout", "80"], timeout=90)
    # the agent commands its robot: non-zero twists in the plane (linear x, y; angular z) once
    # it hears its peer (alone, its command is zero: a peer started late on a loaded machine)
    def moving_in_plane():
        twists = _twists(ros.output(echo))
        return len(twists) >= 5 and np.abs(twists[:, [0, 1, 5]]).max() > 1e-6

    assert _wait(moving_in_plane, 40), ros.output(agents[0])[-2000:]
    assert np.abs(_twists(ros.output(echo))[:, [2, 3, 4]]).max() == 0

    # a gain in range is applied at the next tick; one out of range and a read-only one are not
    ok, reason = _set_parameter(ros, "/polymatch/agent_0", "kappa", 3.0)
    assert ok, reason
    assert _wait(lambda: "kappa 2 -> 3" in ros.output(agents[0]), 10), ros.output(agents[0])
    ok, reason = _set_parameter(ros, "/polymatch/agent_0", "max_linear_speed", -1.0)
    assert not ok and "max_linear_speed" in reason, reason
    ok, reason = _set_parameter(ros, "/polymatch/agent_0", "scene", "other.yaml")
    assert not ok and "read-only" in reason.lower(), reason

    # paused through the agent's own service (std_srvs/SetBool): one zero command at once, then
    # quiet; resumed: it commands again
    said = _probe(ros, "call /polymatch/agent_0/pause true")
    assert "RESULT /polymatch/agent_0/pause True paused" in said, said
    assert _wait(lambda: "robot stopped: paused" in ros.output(agents[0]), 5)
    time.sleep(0.5)
    paused = _twists(ros.output(echo))
    assert np.all(paused[-1] == 0.0), paused[-3:]
    time.sleep(1.0)
    assert len(_twists(ros.output(echo))) == len(paused), "commands while paused"
    assert "resumed" in _probe(ros, "call /polymatch/agent_0/pause false")
    assert _wait(lambda: len(_twists(ros.output(echo))) > len(paused) + 3, 10)
    assert np.abs(_twists(ros.output(echo))[-1]).max() > 0.0

    # the robot dies: the agent sends one zero command, then stays quiet
    ros.kill(robots[0])
    assert _wait(lambda: "robot stopped: measured pose older than" in ros.output(agents[0]), 10)
    time.sleep(1.5)  # ten ticks at 10 Hz
    seen = _twists(ros.output(echo))
    assert np.all(seen[-1] == 0.0), seen[-3:]
    time.sleep(1.5)
    assert len(_twists(ros.output(echo))) == len(seen), "commands after the zero command"
    assert agents[0].poll() is None and agents[1].poll() is None
    # its agent relays no stale pose, so its peer drops it after the peer timeout (1 s)
    assert _wait(lambda: "agent 0 silent for 1 s" in ros.output(agents[1]), 5), (
        ros.output(agents[1])[-2000:]
    )

    # the robot restarted (at its initial pose): its agent drives it again, non-zero commands
    robots[0] = _robot(ros, scene, 0, position_noise=0.0005)
    assert _wait(lambda: len(_twists(ros.output(echo))) > len(seen) + 5, 40), (
        ros.output(agents[0])[-2000:]
    )
    assert np.abs(_twists(ros.output(echo))[-1]).max() > 0.0
    # and its peer takes it back into the sums
    assert _wait(lambda: "agent 0 is back" in ros.output(agents[1]), 10), (
        ros.output(agents[1])[-2000:]
    )


@needs_ros
def test_bridge_run_drives_robots_to_the_noise_floor(ros, tmp_path):
    """Eight first-order robots (A-2), each driven by its bridged agent, match to the noise
    floor (Theorem 4.2 up to the measurement noise)."""
    count = 8
    scene = _scene(tmp_path, SCENE_ROBOTS.format(t_end=25.0, count=count))
    proc = ros.start([PY, "-m", "polymatch_ros.cli", "run", scene, "--mode", "bridge",
                      "--rate", "10", "--position-noise", "0.002", "--angle-noise", "0.002",
                      "--lag", "0.2", "--timeout", "90"], timeout=110)
    rc = ros.wait(proc, 120)
    text = ros.output(proc)
    assert rc == 0, text[-3000:]
    found = re.search(r"converged: matching diameter < (\S+) from t = (\S+)", text)
    assert found, text[-3000:]
    tolerance = float(found.group(1))
    radius = np.linalg.norm(load_scene(scene).model.groups[0].reference, axis=1).max()
    assert tolerance == pytest.approx(noise_floor(0.002, 0.002, radius, 2), rel=1e-5)
    final = re.search(rf"^triangles +{count} +\S+ +\S+ +(\S+) ", text, re.M)
    assert final and float(final.group(1)) < tolerance, text[-2000:]


@needs_ros
def test_second_order_bridge_run_drives_robots_to_the_noise_floor(ros, tmp_path):
    """The shipped second-order scene (A-1): 8 double-integrator robots commanded accelerations
    on cmd_accel from their Odometry, matched to the noise floor; every robot moved."""
    proc = ros.start([PY, "-m", "polymatch_ros.cli", "run", "congruent_triangles_second_order",
                      "--mode", "bridge", "--t-end", "30", "--rate", "10", "--position-noise",
                      "0.002", "--angle-noise", "0.002", "--lag", "0.2", "--robot-log",
                      str(tmp_path), "--timeout", "90"], timeout=110)
    rc = ros.wait(proc, 120)
    text = ros.output(proc)
    assert rc == 0, text[-3000:]
    found = re.search(r"converged: matching diameter < (\S+) from t = (\S+)", text)
    assert found, text[-3000:]
    scene = load_scene(scene_path("congruent_triangles_second_order"))
    radius = np.linalg.norm(scene.model.groups[0].reference, axis=1).max()
    assert float(found.group(1)) == pytest.approx(noise_floor(0.002, 0.002, radius, 2), rel=1e-5)
    final = re.search(r"^triangles +8 +\S+ +\S+ +(\S+) ", text, re.M)
    assert final and float(final.group(1)) < float(found.group(1)), text[-2000:]
    for agent in range(8):
        true_x = np.loadtxt(tmp_path / f"robot_{agent}.txt")[:, 1:3]
        assert np.linalg.norm(true_x[-1] - true_x[0]) > 0.1, f"robot {agent} did not move"


SCENE_CROSSING = """\
name: crossing
dimension: 2
model: {{order: 1, kappa: 1.0, gamma: 1.0}}
integrator: {{method: rkmk4, dt: 0.05}}
time: {{t_end: 16.0}}
convergence: {{tolerance: 0.05}}
formation: {{offsets: [[1.5, 0.0], [-1.5, 0.0], [0.0, 1.5]]}}
safety: {{radius: 0.3, alpha: 2.0}}
groups:
  - {{name: robots, shape: triangle, size: 0.3, count: 3,
     centroids: {{points: [[-2.0, 0.15], [2.0, -0.15], [0.0, -1.0]]}}}}
"""


@needs_ros
@pytest.mark.parametrize("drive", ["holonomic", "unicycle"])
def test_robots_crossing_to_their_formation_places_never_come_closer_than_2r(ros, tmp_path,
                                                                             drive):
    """Robots 0 and 1 swap sides (their formation places lie across each other's path): the
    model alone drives them through each other.  With the safety filter, the robots' logged
    true positions (the oracle: the simulated robots' own log, not the agents' view) stay at
    least 2 r apart (to 1 %: 20 Hz commands, 0.05 s lag), and the formation is reached;
    unicycle bases the same, for the points ahead of their axles (core.unicycle)."""
    scene = _scene(tmp_path, SCENE_CROSSING.format())
    proc = ros.start([PY, "-m", "polymatch_ros.cli", "run", scene, "--mode", "bridge",
                      "--rate", "20", "--lag", "0.05", "--drive", drive, "--hold", "1e9",
                      "--robot-log", str(tmp_path), "--timeout", "90"], timeout=110)
    ros.wait(proc, 120)
    logs = [np.loadtxt(tmp_path / f"robot_{a}.txt") for a in range(3)]
    end = min(data[-1, 0] for data in logs)
    times = np.arange(max(data[0, 0] for data in logs), end, 1.0 / 30.0)
    pos = np.stack([data[np.searchsorted(data[:, 0], times, side="right") - 1, 1:3]
                    for data in logs], axis=1)
    closest = min(np.linalg.norm(pos[:, i] - pos[:, j], axis=1).min()
                  for i in range(3) for j in range(i))
    assert closest >= 0.6 * 0.99, f"robots came {closest:.3f} m close"
    heading = [2 * math.atan2(data[-1, 6], data[-1, 7]) for data in logs]  # about z: qz, qw
    ell = 0.2 if drive == "unicycle" else 0.0
    ahead = np.array([data[-1, 1:3] + ell * np.array([math.cos(h), math.sin(h)])
                      for data, h in zip(logs, heading)])
    places = ahead - np.array([[1.5, 0.0], [-1.5, 0.0], [0.0, 1.5]])
    error = max(np.linalg.norm(places[i] - places[j]) for i in range(3) for j in range(i))
    assert error < 0.05, f"formation error {error:.3f} m at the end ({ros.output(proc)[-1500:]})"
