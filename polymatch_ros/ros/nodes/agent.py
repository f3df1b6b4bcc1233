"""The polytope agent: an rclpy node that steps its own polytope(s) with the core's stepper.

    ros2 run polymatch_ros agent --ros-args -r __ns:=/polymatch -r __node:=agent_3 \\
        -p scene:=config/congruent_triangles.yaml -p agent:=3 [-p mode:=realtime]

One class per mode, all on ``agent_base.AgentBase``: ``lockstep.LockstepAgent``,
``realtime.RealtimeAgent``, ``bridge.BridgeAgent``; ``managed.ManagedAgent`` wraps the chosen
one in a lifecycle node.
"""

from __future__ import annotations

import importlib
import sys
from typing import TYPE_CHECKING

from .. import wire
from ..config.configs import AgentConfig, given_config, pin_config
from ..config.params import RUNTIME
from ..config.resolve import resolve_agent
from ..process.shell import ros_main

if TYPE_CHECKING:
    from ..agents.agent_base import AgentBase
    from ..agents.managed import ManagedAgent


#: each mode's agent class, as module and class name (imported on demand: each its own module)
AGENT_CLASSES: dict[wire.Mode, tuple[str, str]] = {
    wire.Mode.LOCKSTEP: ("polymatch_ros.ros.agents.lockstep", "LockstepAgent"),
    wire.Mode.REALTIME: ("polymatch_ros.ros.agents.realtime", "RealtimeAgent"),
    wire.Mode.BRIDGE: ("polymatch_ros.ros.agents.bridge", "BridgeAgent"),
}


def agent_class(mode: str) -> type[AgentBase]:
    """The agent class of a mode (``AGENT_CLASSES``)."""
    module, name = AGENT_CLASSES[wire.mode_of(mode)]
    cls: type[AgentBase] = getattr(importlib.import_module(module), name)
    return cls


def make_agent(argv: list[str] | None = None) -> ManagedAgent:
    """The managed agent of the mode the parameters ask for (checked before any topic is
    created); its lifecycle node configures and activates itself unless ``autostart`` is off.

    Its parameters hold what it uses (``resolve.resolve_agent``: the scene's gains, integrator,
    step and end time unless given; the scene is loaded there, once); in realtime and bridge
    modes ``RUNTIME`` may be set."""
    from ..agents.managed import ManagedAgent, lifecycle_node

    node = lifecycle_node("agent", wire.namespace(wire.DEFAULT_ENSEMBLE))
    resolved = resolve_agent(given_config(node, AgentConfig))
    config = resolved.config
    pin_config(node, config, RUNTIME if wire.mode_of(config.mode).ticks else ())
    cls = agent_class(config.mode)
    return ManagedAgent(node, lambda n, ex: cls(n, resolved, ex), config.autostart)


def main(args: list[str] | None = None) -> int:
    return ros_main(make_agent, "agent", args)


if __name__ == "__main__":
    sys.exit(main())
