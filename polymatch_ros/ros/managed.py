"""The agent as a managed (lifecycle) node: ``rclpy.lifecycle`` drives what the agent does.

    ros2 run polymatch_ros agent --ros-args -p scene:=... -p agent:=3 -p autostart:=false
    ros2 lifecycle set /polymatch/agent_3 configure      # and activate, deactivate, ...

- configure: loads and checks the scene and the parameters, and builds the mode's agent (its
  publishers, subscriptions and services); a bad scene fails the transition, with the reason
  logged.
- activate: the agent starts (lockstep: rounds once every peer is matched; realtime and
  bridge: on the ensemble's start); activated again after a deactivate, it resumes.
- deactivate: the agent pauses (``control.AgentControl``; bridge: one zero command at once).
- cleanup: releases what configure built (back to unconfigured); shutdown: ends the run.

With ``autostart`` (the default, and what ``polymatch run`` uses) the agent configures and
activates itself, so a plain ``ros2 run`` and every launch-free script work unchanged.
"""

import time

from ..core.errors import PolymatchError
from .process import NodeApp


def lifecycle_node(name, namespace):
    """The agent's ``LifecycleNode`` (``~/change_state``, ``~/get_state`` services)."""
    from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn

    class AgentLifecycleNode(LifecycleNode):
        """Transitions call the ``ManagedAgent`` that owns the node (``self.owner``)."""

        owner = None

        def _answer(self, ok):
            return TransitionCallbackReturn.SUCCESS if ok else TransitionCallbackReturn.FAILURE

        def on_configure(self, state):
            return self._answer(self.owner.configure())

        def on_activate(self, state):
            self.owner.activate(True)
            return super().on_activate(state)

        def on_deactivate(self, state):
            self.owner.activate(False)
            return super().on_deactivate(state)

        def on_cleanup(self, state):
            return self._answer(self.owner.cleanup())

        def on_shutdown(self, state):
            self.owner.shut_down()
            return TransitionCallbackReturn.SUCCESS

    return AgentLifecycleNode(
        name, namespace=namespace, automatically_declare_parameters_from_overrides=False
    )


class ManagedAgent(NodeApp):
    """Runs the mode's agent (``build(node, executor)``) when its lifecycle node is active."""

    def __init__(self, node, build, autostart):
        from rclpy.executors import SingleThreadedExecutor

        self.node, self.build, self.autostart = node, build, autostart
        node.owner = self
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(node)
        self.agent = None
        self.error = None
        self.active = False
        self.ended = False
        self._built = None  # the node's entities before configure: cleanup keeps these

    # -- transitions ---------------------------------------------------------------------
    def configure(self):
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

    def activate(self, on):
        self.active = on
        if self.agent is not None:
            self.agent.control.command("resume" if on else "pause", time.time())

    def cleanup(self):
        self._release()
        return True

    def shut_down(self):
        self.ended = True
        if self.agent is not None:
            self.agent.control.command("stop")

    def _release(self):
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
    def run(self):
        """Autostart: configure and activate; else wait for both.  Then the agent's run."""
        if self.autostart:
            self.node.trigger_configure()
            if self.agent is None:
                raise self.error
            self.node.trigger_activate()
        while not (self.active and self.agent is not None) and not self.ended:
            self.executor.spin_once(timeout_sec=0.1)
        if self.ended:
            return 0
        return self.agent.run()

    def report(self):
        if self.agent is not None:
            self.agent.report()

    def destroy(self):
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
