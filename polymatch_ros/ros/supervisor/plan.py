"""What one `polymatch run` does, decided before anything starts: the ``RunPlan``.

The command line (``polymatch_ros.cli.run``) parses its options into a ``RunOptions`` record;
``build_run_plan`` checks them (every bad option is a one-line error before a process starts)
and decides the run once: the scene, the numerical plan, this host's agents, the packing; the
runner only reads the plan.  Values derived from the scene or the mode (the lead flag, time
scale 1 in bridge mode, the noise-floor tolerance of bridge mode) are in it as decided, never
patched in later.  ``round_rate`` builds its measuring run's plan the same way.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from ...core.errors import ParameterError, PolymatchError
from ...core.robots.robot_commands import bridge_model, noise_floor
from ..config.params import AGENT, ROBOT, Param, check_value
from ..wire.modes import Mode
from .packing import Packing, PackingAsked, choose_packing
from .recovery import RestartPolicy

if TYPE_CHECKING:
    from ...core.scenes.scene import Scene
    from ...core.stepping.simulate import NumericalPlan
    from ..network.discovery import DiscoverySpec

#: each `polymatch run` option that sets a node's parameter: option -> (node, parameter); its
#: value is checked against the parameter's row before anything starts
NODE_OPTIONS: dict[str, tuple[str, str]] = {
    "mode": ("agent", "mode"), "integrator": ("agent", "integrator"), "dt": ("agent", "dt"),
    "t_end": ("agent", "t_end"), "run_id": ("agent", "run_id"), "rate": ("agent", "rate"),
    "time_scale": ("agent", "time_scale"), "peer_timeout": ("agent", "peer_timeout"),
    "delay": ("agent", "delay"), "round_timeout": ("agent", "round_timeout"),
    "max_linear_speed": ("agent", "max_linear_speed"),
    "max_angular_speed": ("agent", "max_angular_speed"),
    "max_linear_accel": ("agent", "max_linear_accel"),
    "max_angular_accel": ("agent", "max_angular_accel"), "drive": ("agent", "drive"),
    "cmd_vel_type": ("agent", "cmd_type"), "lag": ("robot", "lag"),
    "position_noise": ("robot", "position_noise"), "angle_noise": ("robot", "angle_noise"),
}
#: node -> its parameter table
TABLES: dict[str, tuple[Param, ...]] = {"agent": AGENT, "robot": ROBOT}
#: options whose default is not their parameter's: a bridged run's robots measure with noise
#: (a robot node alone measures exactly)
OWN_DEFAULTS = {"position_noise": 0.001, "angle_noise": 0.001}


def node_parameter(option: str) -> Param:
    """The parameter row option ``option`` (a ``RunOptions`` field) sets."""
    node, name = NODE_OPTIONS[option]
    return next(p for p in TABLES[node] if p.name == name)


def option_default(option: str) -> Any:
    """An option's default: its own (``OWN_DEFAULTS``), else its parameter's (None where the
    node resolves it)."""
    if option in OWN_DEFAULTS:
        return OWN_DEFAULTS[option]
    p = node_parameter(option)
    return p.default if p.fixed else None


def _default(option: str) -> Any:
    return field(default=option_default(option))


@dataclass(frozen=True)
class RunOptions:
    """`polymatch run` as asked: the parsed command line, nothing checked yet
    (``build_run_plan`` checks it and decides the run)."""

    scene: str
    mode: str = _default("mode")
    integrator: str | None = _default("integrator")
    dt: float | None = _default("dt")
    t_end: float | None = _default("t_end")
    agents_per_process: int | None = None
    agent_nodes: str = "auto"
    rate: float = _default("rate")
    time_scale: float = _default("time_scale")
    peer_timeout: float = _default("peer_timeout")
    delay: float = _default("delay")
    round_timeout: float = _default("round_timeout")
    hold: float = 1.0
    timeout: float = 600.0
    on_failure: str = "restart"
    ensemble: str = "polymatch"
    isolated: bool = False
    monitor: bool = True
    compare: bool = True
    save: str | None = None
    record: str | None = None
    quiet: bool = False
    verbose: bool = False
    run_records: str | None = None
    logs: str | None = None
    only: str | None = None
    run_id: int | None = None
    discovery: str = "localhost"
    lag: float = _default("lag")
    position_noise: float = _default("position_noise")
    angle_noise: float = _default("angle_noise")
    max_linear_speed: float = _default("max_linear_speed")
    max_angular_speed: float = _default("max_angular_speed")
    max_linear_accel: float = _default("max_linear_accel")
    max_angular_accel: float = _default("max_angular_accel")
    cmd_vel_type: str = _default("cmd_vel_type")
    robot_log: str | None = None
    drive: str = _default("drive")


@dataclass(frozen=True)
class Hosts:
    """Where the ensemble runs: its namespace, the agents of this host, discovery."""

    ensemble: str                      # namespace /<ensemble>
    agents: tuple[int, ...]            # the agents this host runs (--only; else all)
    monitor: bool                      # this host starts the monitor (not --no-monitor)
    lead: bool                         # this host runs the monitor or every agent
    discovery: DiscoverySpec           # how the DDS participants find each other
    isolated: bool = False             # --isolated: a fresh private domain, not the user's
    run_id: int | None = None          # --run-id: the id every message of the run carries;
                                       # None: chosen (``runner``)


@dataclass(frozen=True)
class Timing:
    """How long the run may take, and how the agents step and wait."""

    timeout: float         # wall-clock limit of the whole run (s)
    hold: float            # stop once the diameter stayed under tolerance this long (sim. s)
    rate: float            # realtime: steps per second
    time_scale: float      # realtime: simulated seconds per wall-clock second (bridge: 1)
    peer_timeout: float    # realtime: drop silent peers after this many s
    delay: float           # realtime: injected transport delay (s)
    round_timeout: float   # lockstep: a round fails after this many s if a peer has left


@dataclass(frozen=True)
class Outputs:
    """What the run prints and writes."""

    save: str | None       # npz of the final poses (checked writable, suffix appended)
    run_records: str | None    # every process's run record, JSON lines
    quiet: bool            # no progress, no first line
    verbose: bool          # every agent's final line
    compare: bool          # lockstep: compare with the centralised simulation
    record: str | None = None  # MCAP file of the run's topics (checked writable, suffix appended)
    logs: str | None = None    # a directory: each process's whole output in <name>.log


@dataclass(frozen=True)
class BridgeOptions:
    """The simulated robots of bridge mode and the agents' command limits."""

    lag: float
    position_noise: float
    angle_noise: float
    max_linear_speed: float
    max_angular_speed: float
    max_linear_accel: float
    max_angular_accel: float
    robot_log: str | None      # a directory for the robots' pose logs
    drive: str = "holonomic"   # holonomic | unicycle (differential-drive robots)
    cmd_vel_type: str = "twist_stamped"  # first order: the cmd_vel message (params.CMD_TYPES)


@dataclass(frozen=True)
class RunPlan:
    """One `polymatch run`, checked: the scene, the numerical plan and every option."""

    scene_path: str            # the scene file (a shipped scene resolved)
    scene: Scene               # loaded, --t-end applied; bridge mode: noise-floor tolerance
    numerics: NumericalPlan             # the fixed-step integrator and its dt
    mode: Mode
    hosts: Hosts
    timing: Timing
    outputs: Outputs
    packing: Packing           # agents per process and their nodes (``packing.choose_packing``)
    bridge: BridgeOptions | None = None   # bridge mode only
    on_failure: RestartPolicy = field(default_factory=RestartPolicy)  # --on-failure

    def __post_init__(self) -> None:
        object.__setattr__(self, "mode", Mode(self.mode))  # a mode's name is taken too

    @property
    def realtime(self) -> bool:
        """The agents step on the wall clock (realtime and bridge mode)."""
        return self.mode.ticks

    @property
    def n_agents(self) -> int:
        """Agents of the whole ensemble (on every host)."""
        return int(self.scene.model.n_agents)

    @property
    def every_agent_here(self) -> bool:
        """This host runs every agent of the ensemble."""
        return len(self.hosts.agents) == self.n_agents


def build_run_plan(options: RunOptions) -> RunPlan:
    """The checked ``RunPlan`` of ``options``: the scene loaded and planned once, this host's
    agents and packing decided; one-line errors, before anything starts."""
    from ...console import (
        check_integrator_option,
        load_scene_options,
        naming_dt_option,
        writable_output,
    )
    from ...core.scenes.scene import resolve_scene_path
    from ...core.stepping.simulate import choose_numerics

    check_integrator_option(options.integrator)
    scene_path = resolve_scene_path(options.scene)
    scene = load_scene_options(scene_path, options.t_end)
    bridge, mode = None, Mode(options.mode)
    if mode.drives_robots:
        bridge = _bridge_options(options)
        scene = bridge_scene(scene, bridge, options.only)  # the noise-floor tolerance
    _check_node_options(options)  # what the agents would refuse, refused before they start
    timing = _timing(options, bridge is not None)
    dt = mode.tick_step(timing.rate, timing.time_scale) if mode.ticks else options.dt
    with naming_dt_option(options.dt if mode.exact else None):  # errors first
        numerics = choose_numerics(scene, options.integrator, dt, distributed=True)
    outputs = Outputs(
        save=writable_output(options.save, ".npz") if options.save else None,  # before a run
        run_records=options.run_records, quiet=options.quiet, verbose=options.verbose,
        compare=options.compare,
        record=writable_output(options.record, ".mcap") if options.record else None,
        logs=_log_directory(options.logs) if options.logs else None,
    )
    hosts = _hosts(options, scene.model.n_agents)
    packing = choose_packing(
        PackingAsked(1 if bridge is not None else options.agents_per_process,  # a robot each
                     hosts.monitor, outputs.record is not None, mode, options.agent_nodes,
                     len(hosts.agents) == scene.model.n_agents),
        len(hosts.agents), _localhost(hosts.discovery))
    return RunPlan(scene_path, scene, numerics, mode, hosts, timing, outputs, packing, bridge,
                   RestartPolicy(restart=options.on_failure == "restart"))


def _check_node_options(options: RunOptions) -> None:
    """Each option that sets a node's parameter, checked against its row (type, range,
    choices): one line naming the option."""
    for option in NODE_OPTIONS:
        value = getattr(options, option)
        if value is None:
            continue
        try:
            check_value(node_parameter(option), value)
        except ParameterError as exc:
            flag = "--" + option.replace("_", "-")
            raise ParameterError(f"{flag}: {str(exc).split(': ', 1)[-1]}") from None


def _localhost(discovery: DiscoverySpec) -> bool:
    """The run's processes discover each other on loopback (the participant limit applies)."""
    from ..network.environment import ros_environment

    env = ros_environment()
    return discovery.kind == "localhost" and env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"


def _log_directory(path: str) -> str:
    """``--logs DIR``, made if it is not there; one line if it cannot be written."""
    try:
        os.makedirs(path, exist_ok=True)
    except OSError as exc:
        raise ParameterError(f"--logs: cannot make {path!r}: {exc.strerror}") from None
    if not os.access(path, os.W_OK | os.X_OK):
        raise ParameterError(f"--logs: {path!r} is not writable")
    return os.path.abspath(path)


def _timing(options: RunOptions, bridge: bool) -> Timing:
    return Timing(
        timeout=options.timeout, hold=options.hold, rate=options.rate,
        time_scale=1.0 if bridge else options.time_scale,  # robots move in real time
        peer_timeout=options.peer_timeout, delay=options.delay,
        round_timeout=options.round_timeout,
    )


def _bridge_options(options: RunOptions) -> BridgeOptions:
    return BridgeOptions(
        lag=options.lag, position_noise=options.position_noise,
        angle_noise=options.angle_noise, max_linear_speed=options.max_linear_speed,
        max_angular_speed=options.max_angular_speed, max_linear_accel=options.max_linear_accel,
        max_angular_accel=options.max_angular_accel, robot_log=options.robot_log,
        drive=options.drive, cmd_vel_type=options.cmd_vel_type,
    )


def _hosts(options: RunOptions, n: int) -> Hosts:
    """This host's share of the ensemble: -k, the namespace, --only, discovery."""
    from ..network.discovery import parse_discovery_spec
    from .children import parse_only

    if options.agents_per_process is not None and options.agents_per_process < 1:
        raise PolymatchError("--agents-per-process must be >= 1")
    check_ensemble(options.ensemble)
    agents = tuple(range(n)) if options.only is None else tuple(parse_only(options.only, n))
    spec = parse_discovery_spec(options.discovery)
    if len(agents) < n and not os.environ.get("ROS_DOMAIN_ID"):
        raise ParameterError(
            "--only: set the same ROS_DOMAIN_ID on every host (e.g. export ROS_DOMAIN_ID=17)"
        )
    if len(agents) < n and options.isolated:
        raise ParameterError("--isolated: a run across hosts (--only) needs the same "
                             "ROS_DOMAIN_ID on every host, not a private one")
    if not options.isolated:
        from ..network.environment import user_domain_id

        try:
            user_domain_id()
        except ValueError as exc:
            raise ParameterError(str(exc)) from None
    lead = options.monitor or len(agents) == n
    if options.run_id is not None and options.run_id < 1:
        raise ParameterError(f"--run-id: {options.run_id} is not in 1 .. 2^31 - 1")
    return Hosts(options.ensemble, agents, options.monitor, lead, spec, options.isolated,
                 options.run_id)


def check_ensemble(name: str) -> None:
    """PolymatchError (one line) unless ``/<name>`` is a valid ROS namespace."""
    from rclpy.exceptions import InvalidNamespaceException
    from rclpy.validate_namespace import validate_namespace

    from .. import wire

    try:
        validate_namespace(wire.namespace(name))
    except InvalidNamespaceException:
        raise PolymatchError(
            f"--ensemble: {name!r} is not a valid ROS namespace "
            f"(letters, digits, underscores; not starting with a digit)"
        ) from None


def scene_noise_floor(scene: Scene, position_noise: float, angle_noise: float) -> float:
    """``core.robots.robot_commands.noise_floor`` for the scene's largest vertex radius."""
    radius = max(float(np.max(np.linalg.norm(g.reference, axis=1))) for g in scene.model.groups)
    return float(noise_floor(position_noise, angle_noise, radius, scene.model.dim))


def bridge_scene(scene: Scene, bridge: BridgeOptions, only: str | None) -> Scene:
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
