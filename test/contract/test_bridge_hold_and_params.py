"""A bridged agent's hold (the damped stop, then one zero command) and its parameters: the
shipped file and the ranges a value set while running is checked against."""

import os
import time
from types import SimpleNamespace

import numpy as np
import pytest
import yaml
from ros_harness import REPO, scene_path

from polymatch_ros.core.robots.robot_commands import ZERO, bridge_model
from polymatch_ros.core.scenes.scene import load_scene
from polymatch_ros.ros.agents.bridge import BridgeAgent
from polymatch_ros.ros.config.configs import AgentConfig, config_from
from polymatch_ros.ros.config.params import AGENT, check
from polymatch_ros.ros.config.runtime_params import validate


def test_second_order_hold_brakes_a_moving_robot_then_sends_one_zero():
    """Pause (or a non-finite command): the damped stop each tick while the measured velocity is
    fresh and above STILL, then one zero and quiet; a stale pose: one zero at once."""
    model = bridge_model(load_scene(scene_path("congruent_triangles_second_order")).model)
    grp, sent = model.rotations, []
    agent = object.__new__(BridgeAgent)  # the hold logic alone, without a node
    agent.model, agent.grp, agent.zero_sent, agent.holding = model, grp, False, ""
    agent.config = config_from(AgentConfig, check(AGENT, {"scene": "x", "mode": "bridge",
                                                          "pose_type": "odometry"}))
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


@pytest.mark.parametrize("cmd_type,message_type", [
    ("twist_stamped", "geometry_msgs/msg/TwistStamped"),  # the default: Jazzy's controllers
    ("twist", "geometry_msgs/msg/Twist"),                  # on request
])
def test_cmd_vel_twist_stamped_by_default_twist_on_request(cmd_type, message_type):
    """The bridge's command crosses the wire (CDR) as the asked type and the simulated robot
    that subscribes with the same ``cmd_type`` takes exactly the numbers sent (chosen here)."""
    from builtin_interfaces.msg import Time
    from rclpy.serialization import deserialize_message, serialize_message

    from polymatch_ros.cli import build_parser
    from polymatch_ros.core.robots.robot_commands import Twist
    from polymatch_ros.ros.agents.bridge import command_class
    from polymatch_ros.ros.config.params import ROBOT
    from polymatch_ros.ros.nodes.robot import RobotNode
    from polymatch_ros.ros.supervisor.bridge_run import agent_fields

    defaults = {spec: next(p.default for p in params if p.name == "cmd_type")
                for spec, params in (("agent", AGENT), ("robot", ROBOT))}
    assert defaults == {"agent": "twist_stamped", "robot": "twist_stamped"}
    args = build_parser().parse_args(["run", "x.yaml", "--mode", "bridge"]
                                     + ["--cmd-vel-type", cmd_type] * (cmd_type == "twist"))
    assert args.cmd_vel_type == cmd_type
    options = SimpleNamespace(max_linear_speed=1.0, max_angular_speed=1.0, cmd_vel_type=cmd_type,
                              drive="holonomic", lag=0.05)
    fields = agent_fields(options, order=1)
    assert fields["cmd_type"] == cmd_type
    # the safety filter's latency: the robots' lag plus one robot step (30 Hz)
    assert fields["safety_latency"] == 0.05 + 1 / 30.0

    sent = Twist(np.array([0.25, -0.5, 0.0]), np.array([0.0, 0.0, 0.75]), False)
    clock = SimpleNamespace(now=lambda: SimpleNamespace(to_msg=lambda: Time(sec=7)))
    bridge = SimpleNamespace(  # what BridgeAgent._message reads of its node
        cmd_class=command_class(1, cmd_type),
        config=SimpleNamespace(frame_id="map", command_frame="world"),
        node=SimpleNamespace(get_clock=lambda: clock))
    msg = BridgeAgent._message(bridge, sent)
    cls = type(msg)
    assert f"{cls.__module__.split('.')[0]}/msg/{cls.__name__}" == message_type
    received = deserialize_message(serialize_message(msg), command_class(1, cmd_type))
    if cmd_type == "twist_stamped":
        assert (received.header.stamp.sec, received.header.frame_id) == (7, "map")
    robot = SimpleNamespace(command=None)
    RobotNode._command(robot, received)
    linear, angular, _ = robot.command
    assert linear.tolist() == [0.25, -0.5, 0.0] and angular.tolist() == [0.0, 0.0, 0.75]
