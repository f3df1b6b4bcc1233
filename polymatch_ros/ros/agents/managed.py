"""The agent as a managed (lifecycle) node: ``rclpy.lifecycle`` drives what the agent does.

    ros2 run polymatch_ros agent --ros-args -p scene:=... -p agent:=3 -p autostart:=false
    ros2 lifecycle set /polymatch/agent_3 configure      # and activate, deactivate, ...

- configure: builds the mode's agent (its publishers, subscriptions and services) from the
  scene and the parameters, which the process resolved at its start (a scene file that cannot
  be read is a bad parameter there); what the agent refuses (an agent not in the scene, a
  scene the mode cannot run) fails the transition, with the reason logged.
- activate: the agent starts (lockstep: rounds once every peer is matched; realtime and
  bridge: on the ensemble's start); activated again after a deactivate, it resumes.
- deactivate: the agent pauses (``control.AgentControl``; bridge: one zero command at once).
- cleanup: releases what configure built (back to unconfigured); shutdown: ends the run.

With ``autostart`` (the default, and what ``polymatch run`` uses) the agent configures and
activates itself, so a plain ``ros2 run`` and every launch-free script work unchanged.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from ...core.errors import PolymatchError
from ..process.shell import NodeApp

if TYPE_CHECKING:
    from rclpy.executors import Executor
    from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn

    from .agent_base import AgentBase


def lifecycle_node(name: str, namespace: str) -> LifecycleNode:
    """The agent's ``LifecycleNode`` (``~/change_state``, ``~/get_state`` services)."""
    from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn

    class AgentLifecycleNode(LifecycleNode):
        """Transitions call the ``ManagedAgent`` that owns the node (``self.owner``)."""

        owner: ManagedAgent  # set by the ManagedAgent that owns the node

        def _answer(self, ok: bool) -> TransitionCallbackReturn:
            return TransitionCallbackReturn.SUCCESS if ok else TransitionCallbackReturn.FAILURE

        def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
            return self._answer(self.owner.configure())

        def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
            self.owner.activate(True)
            return super().on_activate(state)

        def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
            self.owner.activate(False)
            return super().on_deactivate(state)

        def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
            return self._answer(self.owner.cleanup())

        def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
            self.owner.shut_down()
            return TransitionCallbackReturn.SUCCESS

    return AgentLifecycleNode(
        name, namespace=namespace, automatically_declare_parameters_from_overrides=False
    )


class ManagedAgent(NodeApp):
    """Runs the mode's agent (``build(node, executor)``) when its lifecycle node is active."""

    def __init__(self, node: LifecycleNode, build: Callable[[LifecycleNode, Executor], AgentBase],
                 autostart: bool) -> None:
        from rclpy.executors import SingleThreadedExecutor

        self.node: LifecycleNode
        self.node, self.build, self.autostart = node, build, autostart
        node.owner = self  # type: ignore[attr-defined]  # lifecycle_node's class has one
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(node)
        self.agent: AgentBase | None = None
        self.error: PolymatchError | None = None
        self.active = False
        self.ended = False
        # the node's entities before configure: cleanup keeps these
        self._built: dict[str, list[Any]] | None = None

    # -- transitions ---------------------------------------------------------------------
    def configure(self) -> bool:
        node = self.node
        self._built = {kind: list(getattr(node, kind)) for kind in _KINDS}
        try:
            self.agent = self.build(node, self.executor)
        except PolymatchError as exc:
            self.error = exc
            if not self.autostart:  # with autostart, the process's one error line says it
                node.get_logger().error(f"configure failed: {exc}")
            self._release()
            return False
        self.error = None
        return True

    def activate(self, on: bool) -> None:
        self.active = on
        if self.agent is not None:
            self.agent.control.command("resume" if on else "pause", time.time())

    def cleanup(self) -> bool:
        self._release()
        return True

    def shut_down(self) -> None:
        self.ended = True
        if self.agent is not None:
            self.agent.control.command("stop")

    def _release(self) -> None:
        """Destroy what configure built (the agent's own lean nodes, then the node's entities)."""
        if self.agent is not None:
            self.agent.release()
        self.agent = None
        node = self.node
        for kind, destroy in _KINDS.items():
            keep = self._built.get(kind, []) if self._built else []
            for entity in [e for e in getattr(node, kind) if e not in keep]:
                getattr(node, destroy)(entity)

    # -- running -------------------------------------------------------------------------
    def run(self) -> int:
        """Autostart: configure and activate; else wait for both.  Then the agent's run."""
        if self.autostart:
            self.node.trigger_configure()
            if self.agent is None:
                assert self.error is not None  # configure failed and kept the reason
                raise self.error
            self.node.trigger_activate()
        while not (self.active and self.agent is not None) and not self.ended:
            self.executor.spin_once(timeout_sec=0.1)
        if self.ended or self.agent is None:  # the wait ends with an agent unless ended
            return 0
        return self.agent.run()

    def report(self) -> None:
        if self.agent is not None:
            self.agent.report()

    def destroy(self) -> None:
        if self.agent is not None:
            self.agent.destroy()
        else:
            super().destroy()


_KINDS = {
    "clients": "destroy_client",
    "publishers": "destroy_publisher",
    "subscriptions": "destroy_subscription",
    "services": "destroy_service",
    "timers": "destroy_timer",
}
