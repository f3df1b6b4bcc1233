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
from dataclasses import replace
from typing import Any

import numpy as np

from ...core.errors import ParameterError
from ...core.robots.robot_commands import bridge_model, noise_floor
from ...core.scenes.scene import Scene
from .. import wire
from ..config.configs import RobotConfig, ros_args
from .children import Child
from .plan import BridgeOptions, RunPlan


def scene_noise_floor(scene: Scene, position_noise: float, angle_noise: float) -> float:
    """``core.robots.robot_commands.noise_floor`` for the scene's largest vertex radius."""
    radius = max(float(np.max(np.linalg.norm(g.reference, axis=1))) for g in scene.model.groups)
    return float(noise_floor(position_noise, angle_noise, radius, scene.model.dim))


def robot_log(directory: str, agent: int) -> str:
    """The pose log file of robot ``agent`` in ``directory``."""
    return os.path.join(os.path.abspath(directory), f"robot_{agent}.txt")


def prepare(scene: Scene, bridge: BridgeOptions, only: str | None) -> Scene:
    """The scene with the noise-floor tolerance; one-line errors for what bridge cannot run
    (``only``: the --only option, which bridge mode does not take)."""
    bridge_model(scene.model)  # d <= 3; second order damped
    for name in ("lag", "position_noise", "angle_noise"):
        value = getattr(bridge, name)
        if not np.isfinite(value) or value < 0:
            raise ParameterError(f"--{name.replace('_', '-')} must be >= 0, got {value:g}")
    if only is not None:
        raise ParameterError("--mode bridge runs every robot on this host (no --only)")
    if bridge.robot_log is not None and not os.path.isdir(bridge.robot_log):
        raise ParameterError(f"--robot-log: {bridge.robot_log} is not a directory")
    floor = scene_noise_floor(scene, bridge.position_noise, bridge.angle_noise)
    return replace(scene, tolerance=max(scene.tolerance, floor))


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
