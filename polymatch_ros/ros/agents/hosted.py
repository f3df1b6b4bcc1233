"""Every agent a node: the ``agent_<i>`` node of each agent a packed process hosts.

A process that hosts K > 1 agents (``-k K``) is one node, ``agents_<first>_<last>``: it steps
its agents together and carries the block exchange.  So that the ROS graph shows each agent as
its own node at any packing, the process also makes one node per agent, ``agent_<i>``, in its
own context (still one DDS participant per process).  A full one (``agent_nodes:=full``) has

- the agent's pose topics for people and tools (``agent_<i>/pose``, ``/twist``,
  ``/final_pose``, ``/final_twist``);
- its services ``~/start``, ``~/stop``, ``~/reset`` and ``~/pause``, applied to the process
  that hosts it (its agents step together), which its answer names;
- the process's fixed parameters, read-only, with ``agent`` its own index and ``host_node``
  the process node, whose runtime parameters (realtime) apply to it.

A lean one (``agent_nodes:=lean``) has the pose topics alone; the services and parameters are
the process node's.  What decides: every entity a process creates makes rmw_fastrtps publish
the participant's whole graph (``ros_discovery_info``) to every participant again, so a
process's start-up grows with the square of its entities.  A full node has about 24 (six
parameter services and four control services of two endpoints each, its writers), a lean one
3 (``polymatch run`` chooses by the agents a process hosts, ``supervisor.packing``).

No agent node has rosout or the type-description service.  A thread of their own serves the
full nodes, asleep in the middleware's wait until a request comes: rclpy rebuilds a wait set
from every entity of an executor's nodes at each spin, and hundreds of agents' services in
the process's executor would slow every round.
"""

from __future__ import annotations

import threading
from collections.abc import Collection, Iterable
from typing import TYPE_CHECKING

from ..config.configs import AgentConfig
from ..config.params import AGENT, read_only_descriptor
from ..wire.control import AgentControl, offer_agent_services

if TYPE_CHECKING:
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.service import Service


def _agent_node(agent: int, namespace: str, full: bool) -> Node:
    """``agent_<i>`` without rosout and the type-description service; ``full``: with
    parameter services.

    It ignores the process's remap rules (``-r __node:=`` names the process node); its topic
    names are resolved by the process node (``wire.publisher(..., resolver=...)``), so the
    user's topic remaps apply to them as to every other topic of the process."""
    from rclpy.node import Node
    from rclpy.parameter import Parameter

    return Node(
        f"agent_{agent}",
        namespace=namespace,
        use_global_arguments=False,
        enable_rosout=False,
        start_parameter_services=full,
        parameter_overrides=[Parameter("start_type_description_service", value=False)],
    )


class HostedAgents:
    """The node of each agent of a packed process (full or lean), and the executor that serves
    the full ones."""

    def __init__(self, host: Node, agents: Iterable[int], config: AgentConfig,
                 control: AgentControl, runtime: Collection[str] = (),
                 full: bool = True) -> None:
        from rclpy.executors import SingleThreadedExecutor

        self.host = host
        namespace = host.get_namespace()
        self.nodes: dict[int, Node] = {a: _agent_node(a, namespace, full) for a in agents}
        self.executor: SingleThreadedExecutor = SingleThreadedExecutor()
        self.services: list[Service] = []
        scope = (f"applied by its process {host.get_fully_qualified_name()} to the "
                 f"{len(self.nodes)} agents it hosts")
        for agent, node in self.nodes.items():
            self.executor.add_node(node)
            if full:
                _mirror_parameters(node, agent, config, runtime, host.get_fully_qualified_name())
                self.services += offer_agent_services(node, control, host.get_logger(), scope)
        self.thread = threading.Thread(target=self._serve, name="hosted_agents", daemon=True)
        if full:  # a lean node has nothing to serve
            self.thread.start()

    def _serve(self) -> None:
        """The thread's loop: answer requests as they come, until the executor shuts down."""
        from rclpy.executors import ExternalShutdownException

        try:
            self.executor.spin()
        except (ExternalShutdownException, RuntimeError):  # the context or executor ended
            pass

    def destroy(self) -> None:
        self.executor.shutdown(timeout_sec=1.0)
        if self.thread.is_alive():
            self.thread.join(timeout=1.0)
        for node in self.nodes.values():
            node.destroy_node()
        self.nodes = {}


def _mirror_parameters(node: Node, agent: int, config: AgentConfig,
                       runtime: Collection[str], host: str) -> None:
    """The process's fixed parameters on an agent's node, read-only; ``agent`` its own."""
    from rcl_interfaces.msg import ParameterDescriptor

    for p in AGENT:
        value = agent if p.name == "agent" else getattr(config, p.name)
        if value is None or p.name in runtime:
            continue
        node.declare_parameter(p.name, value, read_only_descriptor(p))
    node.declare_parameter("host_node", host, ParameterDescriptor(
        description="the process node that hosts this agent: its runtime parameters apply "
        "to this agent, and its services act on every agent it hosts", read_only=True))
