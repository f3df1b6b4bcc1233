"""`polymatch run SCENE --mode bridge`: N simulated robots, N bridged agents and the monitor.

Robot i runs in namespace ``/<ensemble>/robot_<i>`` (topics ``measured_pose``, ``cmd_vel``, or
``cmd_accel`` and Odometry poses for a second-order scene); agent i is remapped onto them.  The
matching diameter the monitor reports comes from measured poses, so it cannot fall below what
the noise makes: the run's tolerance is the larger of the scene's and the noise floor
(``core.command.noise_floor``).  With ``--robot-log DIR`` each robot also writes its true and
measured pose at every step to ``DIR/robot_<i>.txt`` (``robot_sim.POSE_LOG_COLUMNS``).
"""

import os
import sys
from dataclasses import replace

import numpy as np

from ..console import add_number_options, positive_float
from ..core.command import bridge_model, noise_floor
from ..core.errors import ParameterError
from . import wire
from .children import Child

# (flag, type, default, help) of the simulated robots and the agents' command limits
ROBOT_OPTIONS = (
    ("--lag", float, 0.1, "robots' actuator time constant (s, default 0.1)"),
    ("--position-noise", float, 0.001, "std of the measured positions (m, default 0.001)"),
    ("--angle-noise", float, 0.001, "std of the measured orientations (rad, default 0.001)"),
    ("--max-linear-speed", positive_float, 1e6, "commanded speed limit (m/s)"),
    ("--max-angular-speed", positive_float, 1e6, "commanded angular speed limit (rad/s)"),
    ("--max-linear-accel", positive_float, 1e6,
     "second order: commanded acceleration limit (m/s^2)"),
    ("--max-angular-accel", positive_float, 1e6,
     "second order: commanded angular acceleration limit (rad/s^2)"),
)


def add_arguments(p):
    """The options of the simulated robots (bridge mode)."""
    g = p.add_argument_group("bridge mode (simulated robots)")
    add_number_options(g, ROBOT_OPTIONS)
    g.add_argument("--robot-log", metavar="DIR",
                   help="each robot writes its true and measured pose at every step to "
                   "DIR/robot_<i>.txt")


def scene_noise_floor(scene, position_noise, angle_noise):
    """``core.command.noise_floor`` for the scene's largest vertex radius."""
    radius = max(float(np.max(np.linalg.norm(g.reference, axis=1))) for g in scene.model.groups)
    return noise_floor(position_noise, angle_noise, radius, scene.model.dim)


def robot_log(directory, agent):
    """The pose log file of robot ``agent`` in ``directory``."""
    return os.path.join(os.path.abspath(directory), f"robot_{agent}.txt")


def prepare(args, scene):
    """The scene with the noise-floor tolerance; one-line errors for what bridge cannot run."""
    bridge_model(scene.model)  # d <= 3; second order damped
    args.bridge_order = scene.model.order
    for name in ("lag", "position_noise", "angle_noise"):
        value = getattr(args, name)
        if not np.isfinite(value) or value < 0:
            raise ParameterError(f"--{name.replace('_', '-')} must be >= 0, got {value:g}")
    if args.only is not None:
        raise ParameterError("--mode bridge runs every robot on this host (no --only)")
    if args.robot_log is not None and not os.path.isdir(args.robot_log):
        raise ParameterError(f"--robot-log: {args.robot_log} is not a directory")
    args.agents_per_process = 1
    floor = scene_noise_floor(scene, args.position_noise, args.angle_noise)
    return replace(scene, tolerance=max(scene.tolerance, floor))


def agent_args(args):
    """Extra --ros-args of every bridged agent."""
    out = [
        "-p", f"max_linear_speed:={args.max_linear_speed!r}",
        "-p", f"max_angular_speed:={args.max_angular_speed!r}",
    ]
    if args.bridge_order == 2:
        out += ["-p", "pose_type:=odometry",
                "-p", f"max_linear_accel:={args.max_linear_accel!r}",
                "-p", f"max_angular_accel:={args.max_angular_accel!r}"]
    return out


def remaps(agent):
    """Agent ``agent``'s own pose and command topics: its robot's."""
    return [
        "-r", f"measured_pose:=robot_{agent}/measured_pose",
        "-r", f"cmd_vel:=robot_{agent}/cmd_vel",
        "-r", f"cmd_accel:=robot_{agent}/cmd_accel",
    ]


def robots(args, scene_path, env):
    """Start one simulated robot per agent (``Child``ren, ended by PID like the agents)."""
    out = []
    for a in args.agents:
        argv = [
            sys.executable, "-m", "polymatch_ros.ros.robot_sim", "--ros-args",
            "-r", f"__ns:={wire.namespace(args.ensemble)}/robot_{a}",
            "-r", "__node:=robot",
            "-p", f"scene:={os.path.abspath(scene_path)}",
            "-p", f"agent:={a}",
            "-p", f"lag:={args.lag!r}",
            "-p", f"position_noise:={args.position_noise!r}",
            "-p", f"angle_noise:={args.angle_noise!r}",
            "-p", "rate:=30.0",
        ]
        if args.bridge_order == 2:
            argv += ["-p", "pose_type:=odometry"]
        if args.robot_log is not None:
            argv += ["-p", f"pose_log:={robot_log(args.robot_log, a)}"]
        out.append(Child(f"robot_{a}", argv, env))
    return out
