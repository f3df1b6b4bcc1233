"""The parameter tables of the nodes (agent, monitor, robot, recorder): a row per parameter,
its type, default, range and description; declared with descriptors and ranges, checked, and
each holding the value the node uses.  ``configs`` makes a typed configuration of each table.

A node declares its parameters in two steps (``configs.read_config``): first provisionally,
to read what
was given (``-p``, ``--params-file``); then, once it has resolved what was not given (the
scene's gains, step, integrator and end time; the agents it hosts; ...), each with that
effective value and its final descriptor (type, range, read-only unless changeable while
running).  So ``ros2 param get`` answers what the node does, never a placeholder; a parameter
that does not apply (``dt`` outside lockstep, ``mass`` of a first-order model, an optional file
not given) is not declared at all.

``check`` is pure (no ROS): the nodes call it on the given values before they create any
publisher or subscription, and the tests call it directly.  A bad value is a
``ParameterError`` (one line, exit code 2).
"""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

from ...core.errors import ParameterError
from ...core.scenes.limits import MIN_T_END
from ..wire.modes import MODES, MONITOR_MODES, Mode, mode_of

if TYPE_CHECKING:
    from rclpy.node import Node

    from ...core.model import Model

#: what a packed process gives each of its agents (``hosted``)
AGENT_NODES = ("full", "lean", "none")  # not "off": a YAML boolean in -p
#: a first-order bridge's command on cmd_vel: geometry_msgs/TwistStamped (the default: Jazzy's
#: controllers) or Twist
CMD_TYPES = ("twist_stamped", "twist")
#: how a realtime or bridge agent fixes its t = 0: when it starts, on the ensemble's 'start'
#: (control topic, ``/polymatch/start``), or at the given ``start_time``
STARTS = ("now", "control", "at")
#: changeable while running (``ros2 param set``) in realtime and bridge modes, applied at the
#: next tick; every other parameter, and all of them in lockstep, are read-only
RUNTIME = ("kappa", "gamma", "mass", "rate", "max_linear_speed", "max_angular_speed",
           "max_linear_accel", "max_angular_accel")
#: the model's gains: the scene's unless given (realtime, bridge); lockstep runs the scene's
GAINS = ("kappa", "gamma", "mass")


@dataclass(frozen=True)
class Param:
    """A parameter: its default - a value (str, bool, int, float), or only its type (str, int,
    float, list = integer array) where the node resolves it (the scene's value, a derived one)
    or it is optional -, description, (min, max) bounds or None, allowed strings or None."""

    name: str
    default: object
    text: str
    bounds: tuple[float, float] | None = None
    choices: tuple[str, ...] | None = None

    @property
    def kind(self) -> type:
        """The parameter's type: bool, int, float, str or list (of integers)."""
        return self.default if isinstance(self.default, type) else type(self.default)

    @property
    def fixed(self) -> bool:
        """True when the default is a value (not resolved by the node)."""
        return not isinstance(self.default, type)


AGENT = (
    Param("scene", str, "scene file (YAML) or shipped scene name; required; shown as the file "
          "read"),
    Param(
        "agent",
        int,
        "index of the agent this process hosts (0-based over all groups; the first of 'agents' "
        "when it hosts several; default 0)",
        (0, 1_000_000),
    ),
    Param("agents", list, "indices of the agents this process hosts (default: ['agent'])"),
    Param(
        "agents_per_process",
        1,
        "K of the runner's partition: process p hosts agents [pK, (p+1)K)",
        (1, 1_000_000),
    ),
    Param("agent_nodes", "full", "a process hosting several agents gives each a node agent_<i>: "
          "full (its pose topics, services and parameters), lean (its pose topics), none (the "
          "process node alone)", choices=AGENT_NODES),
    Param("mode", Mode.LOCKSTEP.value, " | ".join(MODES), choices=MODES),
    Param("autostart", True, "configure and activate the (lifecycle) agent by itself; false: "
          "wait for the lifecycle transitions (`ros2 lifecycle set`)"),
    Param("integrator", str, "integrator (see `polymatch integrators`): the scene's unless "
          "given, by its resolved name (the scene's `auto` names the method it picks)"),
    Param("dt", float, "lockstep only: step size, the scene's unless given (realtime steps "
          "time_scale/rate, bridge 1/rate)", (MIN_T_END, 1e6)),
    Param("t_end", float, "end time: the scene's unless given", (MIN_T_END, 1e12)),
    Param("rate", 50.0, "realtime: steps, bridge: commands per wall-clock second",
          (0.01, 100000.0)),
    Param("kappa", float, "coupling strength kappa of (A-1)/(A-2): the scene's unless given "
          "(realtime, bridge; lockstep runs the scene's model)", (0.0, 1e6)),
    Param("gamma", float, "damping gamma of (A-1)/(A-2): the scene's unless given (realtime, "
          "bridge; the first-order model and bridged second-order robots need gamma > 0)",
          (0.0, 1e6)),
    Param("mass", float, "second-order model only: mass m of (A-1), the scene's unless given "
          "(realtime, bridge)", (1e-12, 1e6)),
    Param("time_scale", 1.0, "realtime: simulated seconds per wall-clock second", (1e-6, 1e6)),
    Param(
        "start",
        str,
        "realtime, bridge: t = 0 when this agent starts (now), at the epoch of 'start "
        "<epoch>' on the control topic (control), or at 'start_time' (at; the default when "
        "start_time is given, else now)",
        choices=STARTS,
    ),
    Param(
        "start_time",
        float,
        "realtime, bridge: wall-clock time (s since the epoch) of t = 0; given with start at, "
        "else declared once t = 0 is fixed",
        (0.0, 1e12),
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
        str,
        "lockstep: file of this process's state at the start of each step, and where a "
        "restarted process resumes from (declared when given)",
    ),
    Param("discovery_timeout", 30.0, "seconds to wait until every peer is matched", (0.0, 1e6)),
    Param(
        "pose_subscribers",
        0,
        "do not start before this many subscribers listen to the poses",
        (0, 100000),
    ),
    Param(
        "exchange_subscribers",
        0,
        "do not start before this many subscribers (the monitor) listen to the run's exchange",
        (0, 100000),
    ),
    Param(
        "exchange_rate",
        40.0,
        "lockstep: send the states on the run's exchange (what the monitor reads) about this "
        "many times a wall-clock second, at steps every process sends (multiples of a "
        "power-of-two stride) and the last step; 0: every step",
        (0.0, 1e6),
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
    Param("cmd_type", "twist_stamped", "bridge: cmd_vel is twist_stamped (geometry_msgs/"
          "TwistStamped, what Jazzy's diff_drive_controller takes) | twist (Twist)",
          choices=CMD_TYPES),
    Param("command_frame", "world", "bridge: cmd_vel / cmd_accel components in the world | body "
          "frame",
          choices=("world", "body")),
    Param("drive", "holonomic", "bridge: the robot's base: holonomic | unicycle (differential "
          "drive: v and omega of the point axle_offset ahead of its axle)",
          choices=("holonomic", "unicycle")),
    Param("axle_offset", 0.2, "bridge, drive unicycle: the driven point's distance ahead of the "
          "axle (m)", (1e-6, 1e3)),
    Param("safety_radius", 0.0, "bridge: the robots' radius for the safety filter (m; 0: the "
          "scene's safety.radius, none without one)", (0.0, 1e6)),
    Param("safety_alpha", 0.0, "bridge: the safety filter's rate alpha (1/s; 0: the scene's, "
          "or 1)", (0.0, 1e6)),
    Param("safety_latency", 0.05, "bridge: the safety filter looks one command period plus this "
          "far ahead (s: the actuator's lag and the command's transport)", (0.0, 10.0)),
    Param("safety_stale", 0.5, "bridge: a peer's pose older than this (s) is not filtered "
          "against: the robot holds while that peer may be near", (0.0, 1e6)),
    Param(
        "run_id",
        0,
        "run identifier shared by the ensemble; stage and exchange messages with another are "
        "dropped",
        (0, 2**31 - 1),
    ),
)

MONITOR = (
    Param("scene", str, "scene file (YAML) or shipped scene name; required; shown as the file "
          "read"),
    Param(
        "mode",
        Mode.LOCKSTEP.value,
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
    Param("frame_id", "world", "frame of the markers"),
    Param("markers", True, "publish visualization_msgs/MarkerArray"),
    Param("t_end", float, "end time: the scene's unless given; poses stamped later are refused",
          (MIN_T_END, 1e12)),
    Param("run_id", 0, "the run's id, as its agents': exchange messages with another are "
          "dropped", (0, 2**31 - 1)),
    Param(
        "agents_per_process",
        1,
        "K of the agents' partition; with K > 1 each process sends its agents' states in one "
        "message a step or tick (states/block_<b>), and the monitor reads those",
        (1, 1_000_000),
    ),
    Param(
        "report_readers",
        0,
        "read no pose before this many readers listen to every report topic (a run's "
        "recorder: its file then holds every report; agents wait for the monitor's readers)",
        (0, 1000),
    ),
)


ROBOT = (
    Param("scene", str, "scene file (YAML) or shipped scene name: the initial pose; required; "
          "shown as the file read"),
    Param("agent", 0, "the agent whose initial pose the robot starts at", (0, 1_000_000)),
    Param("rate", 50.0, "integration and pose publishing rate (Hz)", (0.1, 10000.0)),
    Param("lag", 0.1, "actuator time constant (s): v' = (v_cmd - v) / lag (second order: of the "
          "acceleration; 0: it follows the command at once)", (0.0, 1e3)),
    Param("max_linear_speed", 1e6, "actuator linear speed limit (m/s)", (0.0, 1e6)),
    Param("max_angular_speed", 1e6, "actuator angular speed limit (rad/s)", (0.0, 1e6)),
    Param("position_noise", 0.0, "standard deviation of the measured position (m)", (0.0, 1e3)),
    Param("angle_noise", 0.0, "standard deviation of the measured orientation (rad)", (0.0, 1.0)),
    Param("seed", int, "noise seed: 1000 + agent unless given", (0, 2**31 - 1)),
    Param("cmd_timeout", 0.5, "stop when no command came for this long (s)", (0.001, 1e6)),
    Param("pose_type", "pose", "measured_pose is pose (PoseStamped) | odometry (second order)",
          choices=("pose", "odometry")),
    Param("cmd_type", "twist_stamped", "cmd_vel is twist_stamped (TwistStamped) | twist (Twist) "
          "(first order)", choices=CMD_TYPES),
    Param("command_frame", "world", "cmd_vel / cmd_accel components in the world | body frame",
          choices=("world", "body")),
    Param("frame_id", "world", "frame_id of the measured pose"),
    Param("drive", "holonomic", "holonomic | unicycle (a differential-drive base: it follows "
          "only linear.x and angular.z of a body-frame cmd_vel)",
          choices=("holonomic", "unicycle")),
    Param("pose_log", str, "file for one line per step: time, true and measured pose "
          "(declared when given)"),
)


RECORDER = (
    Param("output", "", "the MCAP file to write (replaced if it exists); required"),
    Param("duration", 0.0, "stop after this many seconds (0 = at SIGINT or SIGTERM)",
          (0.0, 1e9)),
    Param("scene_file", "", "a scene file to attach (what `polymatch plot` draws); '' = none"),
    Param("t_end", 0.0, "the run's end time, kept with the scene (0 = the scene's)",
          (0.0, 1e12)),
    Param("mode", "", "the run's mode, kept with the scene ('' = not a run)"),
)


def _kind(kind: type) -> str:
    return {bool: "a boolean", int: "an integer", float: "a number", str: "a string"}.get(
        kind, "a list of integers")


def _typed(p: Param, value: Any) -> Any:
    """``value`` as the parameter's type (an integer is a number), or ParameterError."""
    kind = p.kind
    if value is None:
        return None
    if kind in (bool, str):
        ok = isinstance(value, kind)
    elif kind is int:
        ok = isinstance(value, int) and not isinstance(value, bool)
    elif kind is float:
        ok = isinstance(value, (int, float)) and not isinstance(value, bool)
        value = float(value) if ok else value
        ok = ok and math.isfinite(value)
    else:
        ok = isinstance(value, (list, tuple)) and all(
            isinstance(v, int) and not isinstance(v, bool) for v in value
        )
    if not ok:
        raise ParameterError(f"parameter {p.name!r}: expected {_kind(kind)}, got {value!r}")
    return value


def check_value(p: Param, value: Any) -> Any:
    """One parameter's raw value, typed and checked (range, choices), or ParameterError."""
    value = _typed(p, value)
    if p.bounds is not None and value is not None and not p.bounds[0] <= value <= p.bounds[1]:
        raise ParameterError(
            f"parameter {p.name!r}: {value:g} is out of range "
            f"[{p.bounds[0]:g}, {p.bounds[1]:g}]"
        )
    if p.choices is not None and value is not None and value not in p.choices:
        raise ParameterError(
            f"parameter {p.name!r}: expected {' or '.join(p.choices)}, got {value!r}"
        )
    if isinstance(value, (list, tuple)) and any(v < 0 for v in value):
        raise ParameterError(f"parameter {p.name!r}: indices must be >= 0, got {list(value)}")
    return list(value) if isinstance(value, (list, tuple)) else value


def check(spec: Sequence[Param], values: Mapping[str, Any]) -> dict[str, Any]:
    """Check the given {name: raw value} against ``spec`` (types, ranges, choices): the typed
    values, a fixed default where none was given, None where the node resolves the value."""
    out = {}
    for p in spec:
        out[p.name] = check_value(p, values.get(p.name, p.default if p.fixed else None))
    if "scene" in out and not out["scene"]:
        raise ParameterError("parameter 'scene' is required (a scene file)")
    return out


def check_gains(model: Model, mode: str, values: Mapping[str, Any]) -> Model:
    """``model`` with the given gains ({kappa, gamma, mass}: each the model's when absent or
    None), or ParameterError: (A-2) divides by gamma, (A-1) by m, and a bridged second-order
    robot comes to rest only with damping."""
    gains = {k: values[k] for k in GAINS if values.get(k) is not None}
    if "mass" in gains and model.order == 1:
        raise ParameterError("parameter 'mass': the scene's model is first order (A-2), "
                             "without a mass; mass is a parameter of the second-order model (A-1)")
    model = replace(model, **gains)
    if model.order == 1 and not model.gamma > 0:
        raise ParameterError(f"parameter 'gamma': the first-order model (A-2) needs gamma > 0, "
                             f"got {model.gamma:g}")
    if model.order == 2 and mode_of(mode).drives_robots and not model.gamma > 0:
        raise ParameterError("parameter 'gamma': mode bridge: a second-order scene needs gamma "
                             "> 0 (without damping (A-1) never brings a robot to rest)")
    return model


def _descriptor(p: Param, runtime: bool = False, provisional: bool = False) -> Any:
    from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
    from rclpy.parameter import Parameter

    if provisional:  # any type, no range: ``check`` gives the one-line error of a bad value
        return ParameterDescriptor(description=p.text, dynamic_typing=True)
    kind = {bool: Parameter.Type.BOOL, int: Parameter.Type.INTEGER, float: Parameter.Type.DOUBLE,
            str: Parameter.Type.STRING}.get(p.kind, Parameter.Type.INTEGER_ARRAY)
    desc = ParameterDescriptor(description=p.text, read_only=not runtime, type=kind.value)
    if p.choices:
        desc.additional_constraints = "one of: " + ", ".join(p.choices)
    if p.bounds is not None and p.kind is float:
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


def read_only_descriptor(p: Param) -> Any:
    """``p``'s descriptor, read-only (a hosted agent's node mirrors its process's values)."""
    return _descriptor(p)


def given_values(node: Node, spec: Sequence[Param]) -> dict[str, Any]:
    """Declare ``spec`` provisionally on ``node`` (any type, no value) and return what was
    given for it ({name: raw value}; ``-p``, ``--params-file``)."""
    given = {}
    for p in spec:
        node.declare_parameter(p.name, None, _descriptor(p, provisional=True))
        value = node.get_parameter(p.name).value
        if value is not None:
            given[p.name] = list(value) if isinstance(value, (list, tuple)) else value
    return given


def pin(node: Node, spec: Sequence[Param], values: Mapping[str, Any],
        runtime: Collection[str] = ()) -> None:
    """Give each provisionally declared parameter its effective value and final descriptor
    (read-only unless in ``runtime``); one whose value is None does not apply: undeclared."""
    from rclpy.parameter import Parameter

    for p in spec:
        value = check_value(p, values.get(p.name))  # a resolved value passes a given's checks
        if value is None:
            node.undeclare_parameter(p.name)
            continue
        result = node.set_parameters([Parameter(p.name, value=value)])[0]
        if not result.successful:
            raise ParameterError(f"parameter {p.name!r}: {result.reason}")
        node.set_descriptor(p.name, _descriptor(p, p.name in runtime))


def declare_resolved(node: Node, p: Param, value: Any) -> None:
    """Declare ``p`` read-only with ``value`` once the node has fixed it while running (a
    realtime agent's ``start_time``)."""
    if not node.has_parameter(p.name):
        node.declare_parameter(p.name, value, _descriptor(p))

