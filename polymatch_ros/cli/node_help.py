"""``polymatch agent|monitor|robot --help``: a node's parameters, from its parameter table.

The table (``ros.config.params.AGENT``, ``MONITOR``, ``ROBOT``) is the one the
node declares its ROS parameters from, so the help cannot drift from what the node accepts.
Printing it imports no rclpy: no ROS process, no DDS participant.
"""

from __future__ import annotations

import importlib
import textwrap
from collections.abc import Sequence
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from ..ros.config.params import Param

#: node -> (its module, the attribute of its parameter table, what it is)
NODE_TABLES: dict[str, tuple[str, str, str]] = {
    "agent": ("polymatch_ros.ros.config.params", "AGENT",
              "one agent of a scene's ensemble (or several, packed in one process)"),
    "monitor": ("polymatch_ros.ros.config.params", "MONITOR",
                "the ensemble's monitor: diameters, convergence, certificate, stop service"),
    "robot": ("polymatch_ros.ros.config.params", "ROBOT",
              "a simulated robot that a bridged agent drives"),
}

_KINDS = {bool: "bool", int: "int", float: "float", str: "string", list: "int list"}


def wants_help(args: Sequence[str]) -> bool:
    """``-h``/``--help`` among a node's own arguments (before ``--ros-args``)."""
    own = list(args)[: list(args).index("--ros-args")] if "--ros-args" in args else list(args)
    return "-h" in own or "--help" in own


def node_help(name: str) -> str:
    """The help text of node ``name``: usage and one entry per parameter (name, type, default,
    range or choices, meaning)."""
    module, attribute, what = NODE_TABLES[name]
    table = getattr(importlib.import_module(module), attribute)
    lines = [f"usage: polymatch {name} [--ros-args -p NAME:=VALUE ... | --params-file FILE]",
             "",
             f"{what} (ROS 2); the same as `ros2 run polymatch_ros {name} --ros-args ...`.",
             "",
             "parameters (-p NAME:=VALUE):"]
    for p in table:
        lines.append(f"  {p.name}  {_summary(p)}")
        lines += textwrap.wrap(p.text, 92, initial_indent=" " * 6, subsequent_indent=" " * 6)
    return "\n".join(lines)


def _summary(p: Param) -> str:
    kind = _KINDS.get(p.kind, "value")
    parts = [kind, f"default {_shown(p.default)}" if p.fixed else "no fixed default"]
    bounds, choices = p.bounds, p.choices
    if bounds is not None:
        parts.append(f"range [{_shown(float(bounds[0]))}, {_shown(float(bounds[1]))}]")
    if choices:
        parts.append(f"one of {', '.join(choices)}")
    return f"({'; '.join(parts)})"


def _shown(value: object) -> str:
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, float):
        return str(int(value)) if value.is_integer() and abs(value) < 1e7 else f"{value:g}"
    return repr(value) if isinstance(value, str) else str(value)
