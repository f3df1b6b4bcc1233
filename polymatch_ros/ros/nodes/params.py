"""ROS parameters of the agent and the monitor: declared with descriptors and ranges, checked.

``check`` is pure (no ROS): the nodes call it on the declared values before they create
any publisher or subscription, and the tests call it directly.  A bad value is a
``ParameterError`` (one line, exit code 2).
"""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from ...core.errors import ParameterError

if TYPE_CHECKING:
    from rclpy.node import Node

MODES = ("lockstep", "realtime", "bridge")
MONITOR_MODES = ("lockstep", "realtime")
#: changeable while running (``ros2 param set``) in realtime and bridge modes, applied at the
#: next tick; every other parameter, and all of them in lockstep, are read-only
RUNTIME = ("kappa", "gamma", "rate", "max_linear_speed", "max_angular_speed", "max_linear_accel",
           "max_angular_accel")


@dataclass(frozen=True)
class Param:
    """A parameter: default (its type: str, bool, int, float; None = integer array),
    description, (min, max) bounds or None, allowed string values or None."""

    name: str
    default: object
    text: str
    bounds: tuple[float, float] | None = None
    choices: tuple[str, ...] | None = None


AGENT = (
    Param("scene", "", "scene file (YAML) or shipped scene name; required"),
    Param(
        "agent",
        0,
        "index of the agent this process hosts (0-based over all groups)",
        (0, 1_000_000),
    ),
    Param("agents", None, "indices of the agents this process hosts (overrides 'agent')"),
    Param(
        "agents_per_process",
        1,
        "K of the runner's partition: process p hosts agents [pK, (p+1)K)",
        (1, 1_000_000),
    ),
    Param("mode", "lockstep", "lockstep | realtime | bridge", choices=MODES),
    Param("autostart", True, "configure and activate the (lifecycle) agent by itself; false: "
          "wait for the lifecycle transitions (`ros2 lifecycle set`)"),
    Param("integrator", "", "integrator name ('' = the scene's, see `polymatch integrators`)"),
    Param("dt", 0.0, "lockstep step size (0 = the scene's)", (0.0, 1e6)),
    Param("t_end", 0.0, "end time (0 = the scene's)", (0.0, 1e12)),
    Param("rate", 50.0, "realtime: steps, bridge: commands per wall-clock second",
          (0.01, 100000.0)),
    Param("kappa", 0.0, "realtime, bridge: coupling strength (0 = the scene's)", (0.0, 1e6)),
    Param("gamma", 0.0, "realtime, bridge: damping (0 = the scene's)", (0.0, 1e6)),
    Param("time_scale", 1.0, "realtime: simulated seconds per wall-clock second", (1e-6, 1e6)),
    Param(
        "start_time",
        0.0,
        "realtime: wall-clock time (s since the epoch) of t = 0; 0 = when this "
        "agent starts; -1 = wait for 'start <epoch>' on the control topic",
        (-1.0, 1e12),
    ),
    Param(
        "peer_timeout",
        1.0,
        "realtime: seconds of silence after which a peer is dropped from the sums",
        (0.001, 1e6),
    ),
    Param(
        "delay",
        0.0,
        "realtime: injected transport delay (s) before a peer's pose is used",
        (0.0, 1e6),
    ),
    Param(
        "clock_offset_warn",
        0.1,
        "realtime: warn when a peer's clock offset, estimated from its pose stamps, passes "
        "this many seconds",
        (0.0, 1e6),
    ),
    Param(
        "hold_final",
        0.0,
        "seconds to keep the latched final poses alive after the run until 'received' on the "
        "control topic (hosts of a run across hosts without the summary); 0 = do not wait",
        (0.0, 1e6),
    ),
    Param(
        "round_timeout",
        10.0,
        "lockstep: seconds a round waits before it fails if a missing peer has left (the "
        "first two steps: plus discovery_timeout); see stall_timeout",
        (0.001, 1e6),
    ),
    Param(
        "stall_timeout",
        300.0,
        "lockstep: past round_timeout, how long a round keeps waiting for peers that are "
        "still present (slow, not gone); a peer that left fails the round at once",
        (0.001, 1e6),
    ),
    Param(
        "peers_restart",
        False,
        "lockstep: the runner restarts a peer that dies (`polymatch run --on-failure restart`): "
        "a round waits for a peer that left as for a slow one, and keeps a step of its "
        "messages for the peer's resume",
    ),
    Param(
        "checkpoint",
        "",
        "lockstep: file of this process's state at the start of each step, and where a "
        "restarted process resumes from ('' = none)",
    ),
    Param("discovery_timeout", 30.0, "seconds to wait until every peer is matched", (0.0, 1e6)),
    Param(
        "pose_subscribers",
        0,
        "do not start before this many subscribers listen to the poses",
        (0, 100000),
    ),
    Param("frame_id", "world", "frame_id of published poses"),
    Param(
        "max_linear_speed", 1e6, "bridge: commanded linear speed limit (m/s, by norm)", (0.0, 1e6)
    ),
    Param(
        "max_angular_speed",
        1e6,
        "bridge: commanded angular speed limit (rad/s, by norm)",
        (0.0, 1e6),
    ),
    Param("max_linear_accel", 1e6,
          "bridge, second order: commanded linear acceleration limit (m/s^2, by norm)",
          (0.0, 1e6)),
    Param("max_angular_accel", 1e6,
          "bridge, second order: commanded angular acceleration limit (rad/s^2, by norm)",
          (0.0, 1e6)),
    Param(
        "pose_timeout",
        0.5,
        "bridge: a measured pose older than this (s) stops the robot (one zero command)",
        (0.001, 1e6),
    ),
    Param("pose_type", "pose", "bridge: measured_pose is pose (PoseStamped) | odometry "
          "(nav_msgs/Odometry; second order needs its twist)", choices=("pose", "odometry")),
    Param("cmd_type", "twist", "bridge: cmd_vel is twist (Twist) | twist_stamped",
          choices=("twist", "twist_stamped")),
    Param("command_frame", "world", "bridge: cmd_vel / cmd_accel components in the world | body "
          "frame",
          choices=("world", "body")),
    Param(
        "run_id",
        0,
        "run identifier shared by the ensemble; stage messages with another are dropped",
        (0, 2**31 - 1),
    ),
)

MONITOR = (
    Param("scene", "", "scene file (YAML) or shipped scene name; required"),
    Param(
        "mode",
        "lockstep",
        "lockstep: report the latest simulated time all agents reached, at most "
        "'report_rate' Hz; realtime: report at 'rate' Hz from the latest poses (also for "
        "bridged agents)",
        choices=MONITOR_MODES,
    ),
    Param("rate", 10.0, "realtime: reports per second", (0.01, 10000.0)),
    Param(
        "report_rate",
        20.0,
        "lockstep: reports per second at most; every step's poses are still collected, and "
        "the latest step all agents reached is reported within 1/report_rate s",
        (0.01, 10000.0),
    ),
    Param(
        "peer_timeout",
        1.0,
        "realtime: ignore agents silent this long (s); also the markers' lifetime",
        (0.001, 1e6),
    ),
    Param("frame_id", "world", "expected frame_id of poses and frame of the markers"),
    Param("markers", True, "publish visualization_msgs/MarkerArray"),
    Param(
        "t_end", 0.0, "end time (0 = the scene's); poses stamped later are refused", (0.0, 1e12)
    ),
)


def _kind(value: object) -> str:
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, int):
        return "an integer"
    if isinstance(value, float):
        return "a number"
    if isinstance(value, str):
        return "a string"
    return "a list of integers"


def _typed(p: Param, value: Any) -> Any:
    """``value`` as the parameter's type (an integer is a number), or ParameterError."""
    d = p.default
    if value is None:
        return None
    if isinstance(d, bool) or isinstance(d, str):
        ok = isinstance(value, type(d))
    elif isinstance(d, int):
        ok = isinstance(value, int) and not isinstance(value, bool)
    elif isinstance(d, float):
        ok = isinstance(value, (int, float)) and not isinstance(value, bool)
        value = float(value) if ok else value
        ok = ok and math.isfinite(value)
    else:
        ok = isinstance(value, (list, tuple)) and all(
            isinstance(v, int) and not isinstance(v, bool) for v in value
        )
    if not ok:
        raise ParameterError(f"parameter {p.name!r}: expected {_kind(d)}, got {value!r}")
    return value


def check_value(p: Param, value: Any) -> Any:
    """One parameter's raw value, typed and checked (range, choices), or ParameterError."""
    value = _typed(p, value)
    if p.bounds is not None and value is not None and not p.bounds[0] <= value <= p.bounds[1]:
        raise ParameterError(
            f"parameter {p.name!r}: {value:g} is out of range "
            f"[{p.bounds[0]:g}, {p.bounds[1]:g}]"
        )
    if p.choices is not None and value not in p.choices:
        raise ParameterError(
            f"parameter {p.name!r}: expected {' or '.join(p.choices)}, got {value!r}"
        )
    if isinstance(value, (list, tuple)) and any(v < 0 for v in value):
        raise ParameterError(f"parameter {p.name!r}: indices must be >= 0, got {list(value)}")
    return list(value) if isinstance(value, (list, tuple)) else value


def check(spec: Sequence[Param], values: Mapping[str, Any]) -> dict[str, Any]:
    """Check {name: raw value} against ``spec`` (types, ranges, choices); the typed values."""
    out = {}
    for p in spec:
        out[p.name] = check_value(p, values.get(p.name, p.default))
    if "scene" in out and not out["scene"]:
        raise ParameterError("parameter 'scene' is required (a scene file)")
    return out


def _descriptor(p: Param, runtime: bool = False) -> Any:
    from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor

    # dynamic typing: `check` gives the one-line error for a wrong type (and takes `t_end:=2`
    # for a float); the ranges are there for `ros2 param describe`
    desc = ParameterDescriptor(
        description=p.text, read_only=not runtime, dynamic_typing=p.default is not None
    )
    if p.choices:
        desc.additional_constraints = "one of: " + ", ".join(p.choices)
    if p.bounds is not None and isinstance(p.default, float):
        desc.floating_point_range = [
            FloatingPointRange(
                from_value=float(p.bounds[0]), to_value=float(p.bounds[1]), step=0.0
            )
        ]
    elif p.bounds is not None:
        desc.integer_range = [
            IntegerRange(from_value=int(p.bounds[0]), to_value=int(p.bounds[1]), step=1)
        ]
    return desc


def declare(
    node: Node, spec: Sequence[Param], runtime: Collection[str] = ()
) -> dict[str, Any]:
    """Declare ``spec`` on ``node`` (descriptors, ranges) and return the checked values;
    the names in ``runtime`` may be set while the node runs (``runtime_params``)."""
    from rclpy.exceptions import (
        InvalidParameterTypeException,
        InvalidParameterValueException,
        ParameterUninitializedException,
    )
    from rclpy.parameter import Parameter

    raw = {}
    for p in spec:
        initial = Parameter.Type.INTEGER_ARRAY if p.default is None else p.default
        try:
            node.declare_parameter(p.name, initial, _descriptor(p, p.name in runtime))
            raw[p.name] = node.get_parameter(p.name).value
        except ParameterUninitializedException:
            raw[p.name] = None
        except InvalidParameterValueException:
            lo, hi = p.bounds if p.bounds else (None, None)
            raise ParameterError(
                f"parameter {p.name!r}: out of range [{lo:g}, {hi:g}]"
                if p.bounds
                else f"parameter {p.name!r}: invalid value"
            ) from None
        except InvalidParameterTypeException as exc:
            raise ParameterError(f"parameter {p.name!r}: {str(exc).splitlines()[0]}") from None
    return check(spec, raw)
