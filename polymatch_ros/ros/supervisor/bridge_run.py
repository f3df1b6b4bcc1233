"""`polymatch run SCENE --mode bridge`: N simulated robots, N bridged agents and the monitor.

Robot i runs in namespace ``/<ensemble>/robot_<i>`` (topics ``measured_pose``, ``cmd_vel``, or
``cmd_accel`` and Odometry poses for a second-order scene); agent i is remapped onto them, and
both speak ``--cmd-vel-type`` on ``cmd_vel`` (TwistStamped unless ``twist`` is asked for).  The
matching diameter the monitor reports comes from measured poses, so it cannot fall below what
the noise makes: the run's tolerance is the larger of the scene's and the noise floor
(``core.robots.robot_commands.noise_floor``).  With ``--robot-log DIR`` each robot also writes its
true and measured pose at every step to ``DIR/robot_<i>.txt`` (``robot_sim.POSE_LOG_COLUMNS``).

What the agents' safety filter assumes is what the robots do: a robot applies a command for at
most one command period (``cmd_timeout`` = 1 / ``--rate``) and then brakes, and the latency the
filter adds to that period is the robots' lag plus one of their steps (``ROBOT_RATE``).
"""

from __future__ import annotations

import os
import sys
from typing import Any

from ...core.errors import ParameterError
from .. import wire
from ..config.configs import RobotConfig, ros_args
from .children import Child
from .plan import BridgeOptions, RunPlan


def robot_log(directory: str, agent: int) -> str:
    """The pose log file of robot ``agent`` in ``directory``."""
    return os.path.join(os.path.abspath(directory), f"robot_{agent}.txt")


#: the simulated robots' integration and pose rate (Hz)
ROBOT_RATE = 30.0


def agent_fields(bridge: BridgeOptions, order: int) -> dict[str, Any]:
    """What every bridged agent's configuration (``AgentConfig``) takes from the robots
    (``order``: the scene model's)."""
    out: dict[str, Any] = dict(
        safety_latency=bridge.lag + 1.0 / ROBOT_RATE,
        max_linear_speed=bridge.max_linear_speed,
        max_angular_speed=bridge.max_angular_speed,
        drive=bridge.drive,
        cmd_type=bridge.cmd_vel_type,
    )
    if order == 2:
        out.update(pose_type="odometry", max_linear_accel=bridge.max_linear_accel,
                   max_angular_accel=bridge.max_angular_accel)
    return out


def remaps(agent: int) -> dict[str, str]:
    """Agent ``agent``'s own pose and command topics: its robot's."""
    return {topic: f"robot_{agent}/{topic}" for topic in ("measured_pose", "cmd_vel", "cmd_accel")}


def robot_config(plan: RunPlan, bridge: BridgeOptions, agent: int) -> RobotConfig:
    """The configuration of robot ``agent`` of ``plan``."""
    log = None if bridge.robot_log is None else robot_log(bridge.robot_log, agent)
    second = plan.scene.model.order == 2
    return RobotConfig(
        scene=os.path.abspath(plan.scene_path), agent=agent, lag=bridge.lag,
        position_noise=bridge.position_noise, angle_noise=bridge.angle_noise, rate=ROBOT_RATE,
        cmd_timeout=1.0 / plan.timing.rate, drive=bridge.drive, cmd_type=bridge.cmd_vel_type,
        pose_type="odometry" if second else "pose", pose_log=log,
    )


def robots(plan: RunPlan, env: dict[str, str]) -> list[Child]:
    """Start one simulated robot per agent (``Child``ren, ended by PID like the agents)."""
    bridge = plan.bridge
    if bridge is None:
        raise ParameterError("simulated robots run in bridge mode only")
    out = []
    for a in plan.hosts.agents:
        argv = [sys.executable, "-m", "polymatch_ros.ros.nodes.robot", "--ros-args"]
        argv += ros_args(robot_config(plan, bridge, a), node="robot",
                         namespace=f"{wire.namespace(plan.hosts.ensemble)}/robot_{a}")
        out.append(Child(f"robot_{a}", argv, env, log_dir=plan.outputs.logs))
    return out
