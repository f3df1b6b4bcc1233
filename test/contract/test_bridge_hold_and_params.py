"""A bridged agent's hold (the damped stop, then one zero command) and its parameters: the
shipped file and the ranges a value set while running is checked against."""

import os
import time
from types import SimpleNamespace

import numpy as np
import yaml
from ros_harness import REPO, scene_path

from polymatch_ros.core.command import ZERO, bridge_model
from polymatch_ros.core.scene import load_scene
from polymatch_ros.ros.nodes.bridge import BridgeAgent
from polymatch_ros.ros.nodes.params import AGENT, check
from polymatch_ros.ros.nodes.runtime_params import validate


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
