"""Robots in the loop: simulated robots driven by bridged agents match (their logged true
poses), stop when their pose goes stale, and take gains changed while running (the command
itself: test/core/test_bridge_command.py)."""

import math
import os
import re
import textwrap
import time

import numpy as np
import pytest
from ros_harness import PY, REPO, needs_ros
from scipy.spatial.transform import Rotation

from benchmarks.hosts.runs import scene_with
from polymatch_ros.core.scenes.scene import load_scene
from polymatch_ros.ros.config.configs import AgentConfig, RobotConfig, ros_args

PARAMS_FILE = os.path.join(REPO, "config", "params", "bridge_agent.yaml")

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


# robots (each beside its agent's process) in the runs to the noise floor: the claim does not
# depend on their number, and each costs two processes
BRIDGE_ROBOTS = 4


def _scene(tmp_path, text, name="scene.yaml"):
    path = tmp_path / name
    path.write_text(text)
    return str(path)


















PARAMS_FILE = os.path.join(REPO, "config", "params", "bridge_agent.yaml")






# -- robots in the loop (multi-process) ----------------------------------------------

SET_PARAMETER = textwrap.dedent("""\
    import sys
    import rclpy
    from rcl_interfaces.srv import SetParameters
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from polymatch_ros.ros.wire.service_call import call_service
    rclpy.init()
    node = Node("param_setter")
    request = SetParameters.Request()
    request.parameters = [Parameter(sys.argv[2], value=eval(sys.argv[3])).to_parameter_msg()]
    answer = call_service(node, SetParameters, sys.argv[1] + "/set_parameters", request, 20.0)
    assert answer.answered, answer.failure
    result = answer.response.results[0]
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
    argv = [PY, "-m", "polymatch_ros.ros.nodes.robot", "--ros-args"] + ros_args(
        RobotConfig(scene=scene, agent=agent, **params), namespace=f"/polymatch/robot_{agent}",
        node="robot")
    return ros.start(argv, timeout=100, name=f"robot {agent}")


@needs_ros
def test_runtime_gain_pause_service_killed_and_restarted_robot(ros, tmp_path):
    """A gain set at runtime, a pause (one zero command, then quiet), a killed robot (one zero
    command, then quiet) and the same robot restarted (driven again)."""
    scene = _scene(tmp_path, SCENE_ROBOTS.format(t_end=80.0, count=2))
    robots = [_robot(ros, scene, a, position_noise=0.0005) for a in range(2)]
    agents = []
    for a in range(2):
        argv = [PY, "-m", "polymatch_ros.ros.nodes.agent", "--ros-args"] + ros_args(
            AgentConfig(scene=scene, agent=a, start="now"), node=f"agent_{a}",
            remaps={t: f"robot_{a}/{t}" for t in ("measured_pose", "cmd_vel")},
            params_file=PARAMS_FILE)
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


def _floor(sigma_p, sigma_theta, radius, dim):
    """The noise floor written out: two agents' measured vertices differ by two position errors
    (sigma_p per coordinate) and two orientation errors times the vertex radius, standard
    deviation sqrt(2) (sigma_p sqrt(d) + sigma_theta r); six of them cover the pairs' maximum."""
    return 6.0 * math.sqrt(2.0) * (sigma_p * math.sqrt(dim) + sigma_theta * radius)


def _true_diameters(log_dir, count, reference):
    """The matching diameter of the robots' true poses in their pose logs (time, x y z, quaternion
    x y z w, then the measured pose), brute force over pairs of robots and vertices: at the
    first line each robot logged and at its last."""
    dim = reference.shape[1]
    ends = []
    for row in (0, -1):
        verts = []
        for agent in range(count):
            line = np.loadtxt(log_dir / f"robot_{agent}.txt", ndmin=2)[row]
            rot = Rotation.from_quat(line[4:8]).as_matrix()[:dim, :dim]
            verts.append(line[1:1 + dim] + reference @ rot.T)
        ends.append(max(float(np.linalg.norm(verts[i] - verts[j], axis=1).max())
                        for i in range(count) for j in range(i + 1, count)))
    return ends


def _check_matched_to_the_floor(text, scene, log_dir, count):
    """The runner states the noise floor as its tolerance and converged below it; the robots'
    logged true poses (not what the agents measured) end below it, from well above it."""
    found = re.search(r"converged: matching diameter < (\S+) from t = (\S+)", text)
    assert found, text[-3000:]
    reference = scene.model.groups[0].reference
    floor = _floor(0.002, 0.002, float(np.linalg.norm(reference, axis=1).max()), scene.model.dim)
    assert float(found.group(1)) == pytest.approx(floor, rel=1e-5)
    final = re.search(rf"^triangles +{count} +\S+ +\S+ +(\S+) ", text, re.M)
    assert final and float(final.group(1)) < floor, text[-2000:]
    first, last = _true_diameters(log_dir, count, reference)
    assert first > 10 * floor and last < floor, (first, last, floor)


@needs_ros
@pytest.mark.parametrize("cmd_vel_type", ["twist_stamped", "twist"])
def test_bridge_run_drives_robots_to_the_noise_floor(ros, tmp_path, cmd_vel_type):
    """Four first-order robots (A-2), each driven by its bridged agent, match to the noise
    floor (Theorem 4.2 up to the measurement noise), with commands on cmd_vel of either type
    (robots that took no command would not move): their logged true poses end below it."""
    count = BRIDGE_ROBOTS
    scene = _scene(tmp_path, SCENE_ROBOTS.format(t_end=25.0, count=count))
    proc = ros.start([PY, "-m", "polymatch_ros.cli", "run", scene, "--mode", "bridge",
                      "--rate", "10", "--position-noise", "0.002", "--angle-noise", "0.002",
                      "--lag", "0.2", "--cmd-vel-type", cmd_vel_type, "--robot-log", str(tmp_path),
                      "--timeout", "90"],
                     timeout=110)
    rc = ros.wait(proc, 120)
    text = ros.output(proc)
    assert rc == 0, text[-3000:]
    _check_matched_to_the_floor(text, load_scene(scene), tmp_path, count)


@needs_ros
def test_second_order_bridge_run_drives_robots_to_the_noise_floor(ros, tmp_path):
    """The shipped second-order scene (A-1), with four agents: double-integrator robots
    commanded accelerations on cmd_accel from their Odometry, matched to the noise floor
    (their logged true poses)."""
    scene = scene_with(tmp_path, "congruent_triangles_second_order", BRIDGE_ROBOTS)
    proc = ros.start([PY, "-m", "polymatch_ros.cli", "run", scene,
                      "--mode", "bridge", "--t-end", "30", "--rate", "10", "--position-noise",
                      "0.002", "--angle-noise", "0.002", "--lag", "0.2", "--robot-log",
                      str(tmp_path), "--timeout", "90"], timeout=110)
    rc = ros.wait(proc, 120)
    text = ros.output(proc)
    assert rc == 0, text[-3000:]
    _check_matched_to_the_floor(text, load_scene(scene), tmp_path, BRIDGE_ROBOTS)


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
    unicycle bases the same, for the points ahead of their axles (core.robots.unicycle)."""
    scene = _scene(tmp_path, SCENE_CROSSING.format())
    proc = ros.start([PY, "-m", "polymatch_ros.cli", "run", scene, "--mode", "bridge",
                      "--rate", "20", "--lag", "0.05", "--drive", drive, "--hold", "1e9",
                      "--max-linear-speed", "1.0", "--max-angular-speed", "4.0",
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
