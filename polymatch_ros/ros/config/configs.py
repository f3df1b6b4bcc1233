"""One typed, frozen configuration per node, made from its parameter table; the one way to write
it on a command line (``ros_args``) and the one way to read it back in the node
(``read_config``).

Each class's fields are its table's rows (``params.AGENT``, ``MONITOR``, ``ROBOT``,
``RECORDER``): the same names, types and defaults, in the same order
(``test/contract/test_configs.py`` holds them to it).  A field whose row names only a type is
None until the node resolves it (the scene's value, a derived one) or, when it is optional,
while it is not given.

A process that starts a node builds its configuration (``AgentConfig(scene=..., mode=...)``)
and passes ``ros_args(config, ...)``: ``-p name:=value`` for every field given and not its
table's default, rendered as the node's YAML reads it back, with the node's remaps.  The node
reads it with ``read_config`` (declare, check, resolve, pin: ``params.declare``) and uses the
typed fields: there is no other place where a parameter is named by a string.
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar, TypeVar

from .params import AGENT, MONITOR, RECORDER, ROBOT, Param, check, given_values, pin

if TYPE_CHECKING:
    from rclpy.node import Node


@dataclass(frozen=True)
class AgentConfig:
    """An agent process's parameters (``params.AGENT``)."""

    table: ClassVar[tuple[Param, ...]] = AGENT
    scene: str | None = None
    agent: int | None = None
    agents: list[int] | None = None
    agents_per_process: int = 1
    agent_nodes: str = "full"
    mode: str = "lockstep"
    autostart: bool = True
    integrator: str | None = None
    dt: float | None = None
    t_end: float | None = None
    rate: float = 50.0
    kappa: float | None = None
    gamma: float | None = None
    mass: float | None = None
    time_scale: float = 1.0
    start: str | None = None
    start_time: float | None = None
    peer_timeout: float = 1.0
    delay: float = 0.0
    clock_offset_warn: float = 0.1
    hold_final: float = 0.0
    round_timeout: float = 10.0
    stall_timeout: float = 300.0
    peers_restart: bool = False
    checkpoint: str | None = None
    discovery_timeout: float = 30.0
    pose_subscribers: int = 0
    exchange_subscribers: int = 0
    exchange_rate: float = 40.0
    frame_id: str = "world"
    max_linear_speed: float = 1e6
    max_angular_speed: float = 1e6
    max_linear_accel: float = 1e6
    max_angular_accel: float = 1e6
    pose_timeout: float = 0.5
    pose_type: str = "pose"
    cmd_type: str = "twist_stamped"
    command_frame: str = "world"
    drive: str = "holonomic"
    axle_offset: float = 0.2
    safety_radius: float = 0.0
    safety_alpha: float = 0.0
    safety_latency: float = 0.05
    safety_stale: float = 0.5
    run_id: int = 0

    @property
    def hosted(self) -> list[int]:
        """The agents this process hosts (resolved: ``agents``)."""
        assert self.agents is not None, "resolved by resolve.resolve_agent"
        return self.agents


@dataclass(frozen=True)
class MonitorConfig:
    """The monitor's parameters (``params.MONITOR``)."""

    table: ClassVar[tuple[Param, ...]] = MONITOR
    scene: str | None = None
    mode: str = "lockstep"
    rate: float = 10.0
    report_rate: float = 20.0
    peer_timeout: float = 1.0
    frame_id: str = "world"
    markers: bool = True
    t_end: float | None = None
    run_id: int = 0
    agents_per_process: int = 1
    report_readers: int = 0


@dataclass(frozen=True)
class RobotConfig:
    """A simulated robot's parameters (``params.ROBOT``)."""

    table: ClassVar[tuple[Param, ...]] = ROBOT
    scene: str | None = None
    agent: int = 0
    rate: float = 50.0
    lag: float = 0.1
    max_linear_speed: float = 1e6
    max_angular_speed: float = 1e6
    position_noise: float = 0.0
    angle_noise: float = 0.0
    seed: int | None = None
    cmd_timeout: float = 0.5
    pose_type: str = "pose"
    cmd_type: str = "twist_stamped"
    command_frame: str = "world"
    frame_id: str = "world"
    drive: str = "holonomic"
    pose_log: str | None = None


@dataclass(frozen=True)
class RecorderConfig:
    """The recorder's parameters (``params.RECORDER``; its topic lists: ``ros_args(lists=)``)."""

    table: ClassVar[tuple[Param, ...]] = RECORDER
    output: str = ""
    duration: float = 0.0
    scene_file: str = ""
    t_end: float = 0.0
    mode: str = ""


Config = AgentConfig | MonitorConfig | RobotConfig | RecorderConfig
C = TypeVar("C", AgentConfig, MonitorConfig, RobotConfig, RecorderConfig)
CONFIGS: tuple[type[Config], ...] = (AgentConfig, MonitorConfig, RobotConfig, RecorderConfig)


def config_values(config: Config) -> dict[str, Any]:
    """{name: value} of every field of ``config`` (lists copied)."""
    return {f.name: _copied(getattr(config, f.name)) for f in dataclasses.fields(config)}


def _copied(value: Any) -> Any:
    return list(value) if isinstance(value, (list, tuple)) else value


def config_from(cls: type[C], values: Mapping[str, Any]) -> C:
    """The configuration of ``cls`` holding ``values`` (names of its table; others: an error)."""
    return cls(**{k: _copied(v) for k, v in values.items()})


# a string the node's YAML reads back as that string, unquoted
_PLAIN = re.compile(r"[A-Za-z0-9_./~+-][A-Za-z0-9_./~+=@-]*")


def render_value(value: Any) -> str:
    """``value`` as the YAML of a ``-p name:=value`` argument: true/false, an integer, a float
    that reads back as a float (``1.0``, ``1e-12``), ``[a,b]``, or a string (quoted where YAML
    would read another type or a plain form would not parse)."""
    import yaml

    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, (list, tuple)):
        return "[" + ",".join(render_value(v) for v in value) + "]"
    text = str(value)
    if _PLAIN.fullmatch(text) and not _number(text) and yaml.safe_load(text) == text:
        return text
    return "'" + text.replace("'", "''") + "'"


def _number(text: str) -> bool:
    """``text`` reads as a number (``1e-3`` too, which rcl's YAML takes for a float)."""
    try:
        float(text)
    except ValueError:
        return False
    return True


def ros_args(config: Config | None = None, *, namespace: str | None = None,
             node: str | None = None, remaps: Mapping[str, str] | None = None,
             lists: Mapping[str, Sequence[str]] | None = None,
             params_file: str | None = None) -> list[str]:
    """The ``--ros-args`` arguments (without that flag) of a node: its namespace and name,
    ``remaps`` ({from: to}), a parameter file, then every field of ``config`` that is given
    (not None) and not its table's default, and string arrays ``lists`` ({name: [..]}: the
    recorder's topics)."""
    out: list[str] = []
    rules = dict(remaps or {})
    if namespace is not None:
        rules = {"__ns": namespace, **rules}
    if node is not None:
        rules["__node"] = node
    for source, target in rules.items():
        out += ["-r", f"{source}:={target}"]
    given: dict[str, Any] = {}
    if config is not None:
        table = {p.name: p for p in config.table}
        for name, value in config_values(config).items():
            p = table[name]
            if p.kind is float and isinstance(value, int) and not isinstance(value, bool):
                value = float(value)
            if value is not None and not (p.fixed and _same(value, p.default)):
                given[name] = value
    given.update(lists or {})
    if params_file is not None:  # before the values given here, which take precedence
        out += ["--params-file", params_file]
    for name, value in given.items():
        out += ["-p", f"{name}:={render_value(value)}"]
    return out


def _same(value: Any, default: Any) -> bool:
    """The value is its default (of the same type: ``1`` is not the float ``1.0``)."""
    return type(value) is type(default) and value == default


def given_config(node: Node, cls: type[C]) -> C:
    """Declare ``cls``'s table on ``node`` provisionally and return what was given (``-p``,
    ``--params-file``), checked: fixed defaults where not given, None where the node
    resolves the value (``params.check``)."""
    return config_from(cls, check(cls.table, given_values(node, cls.table)))


def pin_config(node: Node, config: Config, runtime: Collection[str] = ()) -> None:
    """Give every parameter of ``config``'s table its effective value and final descriptor
    (``params.pin``: read-only unless in ``runtime``; None: not declared)."""
    pin(node, config.table, config_values(config), runtime)


def read_config(node: Node, cls: type[C], resolve: Callable[[C], C] | None = None,
                runtime: Collection[str] = ()) -> C:
    """The node's typed configuration: given, checked, resolved (``resolve``) and declared with
    the values the node uses."""
    config = given_config(node, cls)
    if resolve is not None:
        config = resolve(config)
    pin_config(node, config, runtime)
    return config
