"""The polytope agent: an rclpy node that steps its own polytope(s) with the core's stepper.

    ros2 run polymatch_ros agent --ros-args -r __ns:=/polymatch -r __node:=agent_3 \\
        -p scene:=config/congruent_triangles.yaml -p agent:=3 [-p mode:=realtime]

One class per mode, all on ``agent_base.AgentBase``: ``lockstep.LockstepAgent``,
``realtime.RealtimeAgent``, ``bridge.BridgeAgent``; ``managed.ManagedAgent`` wraps the chosen
one in a lifecycle node.
"""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING

from ...core.errors import ParameterError
from .. import wire
from .params import AGENT, RUNTIME, declare
from .process import ros_main

if TYPE_CHECKING:
    from .agent_base import AgentBase
    from .managed import ManagedAgent


def agent_class(mode: str) -> type[AgentBase]:
    """The agent class of a mode (imported on demand: each mode's module is its own)."""
    if mode == "lockstep":
        from .lockstep import LockstepAgent

        return LockstepAgent
    if mode == "bridge":
        from .bridge import BridgeAgent

        return BridgeAgent
    from .realtime import RealtimeAgent

    return RealtimeAgent


def make_agent(argv: list[str] | None = None) -> ManagedAgent:
    """The managed agent of the mode the parameters ask for (checked before any topic is
    created); its lifecycle node configures and activates itself unless ``autostart`` is off."""
    from .managed import ManagedAgent, lifecycle_node

    node = lifecycle_node("agent", wire.namespace(wire.DEFAULT_ENSEMBLE))
    mode = declare(node, [p for p in AGENT if p.name == "mode"])["mode"]
    rest = [p for p in AGENT if p.name != "mode"]
    params = dict(declare(node, rest, RUNTIME if mode != "lockstep" else ()), mode=mode)
    if mode == "lockstep" and (params["kappa"] or params["gamma"]):
        raise ParameterError(
            "parameters 'kappa', 'gamma': realtime and bridge only (lockstep runs the "
            "scene's model, to equal the centralised simulation)"
        )
    cls = agent_class(mode)
    return ManagedAgent(node, lambda n, ex: cls(n, params, ex), params["autostart"])


def main(args: list[str] | None = None) -> int:
    return ros_main(make_agent, "agent", args)


if __name__ == "__main__":
    sys.exit(main())
