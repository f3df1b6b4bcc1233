"""Start, stop, pause, reset: the services of the ensemble and of each agent.

Ensemble-wide, in the ensemble's namespace, hosted once (by the monitor; by the runner's own
node on a host that runs every agent and no monitor):

  /<ensemble>/start   std_srvs/Trigger  realtime/bridge: t = 0 on every agent, START_LEAD s
                                        from the call (again: the same epoch, re-sent)
  /<ensemble>/stop    std_srvs/Trigger  every agent ends; lockstep agents all at the same step
  /<ensemble>/pause   std_srvs/SetBool  true: hold, false: go on (see ``AgentControl``)
  /<ensemble>/reset   std_srvs/Trigger  realtime: every agent back to its initial state at the
                                        next tick; lockstep and bridge: refused

Each agent offers the same four under its own node (``/<ensemble>/agent_3/pause``) for the
agents of its process alone (a process hosting several agents offers them on its own node and
on each agent's, ``hosted``).  A service is one-to-one and the ensemble is many: the
ensemble's services broadcast one command on the ``control`` topic
(``polymatch_interfaces/msg/ControlCommand``, RELIABLE: START, STOP, PAUSE, RESUME, RESET with
a wall-clock epoch, RECEIVED), so that one wall-clock epoch reaches every agent.  The topic is the
services' transport and the runner's ``received`` handshake; people and programs call the
services.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from .. import wire

if TYPE_CHECKING:
    from rclpy.client import Client
    from rclpy.impl.rcutils_logger import RcutilsLogger
    from rclpy.node import Node
    from rclpy.service import Service
    from rclpy.task import Future

#: (accepted, message for a service's caller)
Answer = tuple[bool, str]

START_LEAD = 0.5  # s between a start/reset request and the epoch it announces

COMMANDS = ("start", "stop", "pause", "resume", "reset", "received")


EPOCH_VERBS = ("start", "pause", "resume", "reset")


def command_message(verb: str, epoch: float | None = None) -> Any:
    """The ``ControlCommand`` of a verb (``COMMANDS``) and, for EPOCH_VERBS, its wall-clock
    epoch (s since the Unix epoch)."""
    from polymatch_interfaces.msg import ControlCommand

    msg = ControlCommand(command=COMMANDS.index(verb))
    if epoch is not None:
        msg.epoch.sec, msg.epoch.nanosec = divmod(int(round(epoch * 1e9)), 1_000_000_000)
    return msg


def parse_command(msg: Any) -> tuple[str, float | None] | None:
    """(verb, epoch or None) of a ControlCommand; None if it is not a valid one."""
    if msg.command >= len(COMMANDS) or msg.epoch.nanosec >= 1_000_000_000:
        return None
    verb = COMMANDS[msg.command]
    epoch = msg.epoch.sec + 1e-9 * msg.epoch.nanosec
    if verb not in EPOCH_VERBS:
        return verb, None
    return (verb, epoch) if epoch > 0 else None


def describe_command(msg: Any) -> str:
    """A ControlCommand as one line for a log (``pause 1764363000.123``)."""
    command = parse_command(msg)
    if command is None:
        return f"command {msg.command} (epoch {msg.epoch.sec}.{msg.epoch.nanosec:09d})"
    verb, epoch = command
    return verb if epoch is None else f"{verb} {epoch:.3f}"


LOCKSTEP_START = "lockstep agents start once every peer is matched"


def reset_refusal(mode: wire.Mode) -> str | None:
    """Why ``reset`` does not apply in this mode, or None (realtime)."""
    if mode.exact:
        return "a lockstep run is reproducible: start a new run to begin again"
    if mode.drives_robots:
        return "a bridged agent's state is its robot's measured pose: move the robot"
    return None


class AgentControl:
    """What an agent process was told, by the control topic or by its own services.

    ``stop_requested``: end the run (lockstep: every process agrees on the step).
    ``start_epoch``: wall-clock time of t = 0 (realtime/bridge; the first start wins).
    ``paused``: lockstep processes start no new round (their peers wait, and a wait while
    paused does not count towards the round timeout); realtime agents hold their state while
    the shared clock runs on, publishing it at every tick so that no peer times them out;
    bridge agents command zero at once.  On resume every agent goes on at the shared clock's
    current tick.
    ``reset_epoch``: realtime agents go back to their initial state at the first tick past it.
    ``final_received``: the lead host has every final pose (runs across hosts).
    A pause, resume or reset is applied once per epoch: the same command again (``replays``)
    is one already applied, delivered twice (a DDS writer's history re-sent to a reader that
    matched it anew), and applying it again would send a converged ensemble back to its initial
    state.
    """

    def __init__(self, mode: str, on_pause: Callable[[bool], None] | None = None) -> None:
        self.mode = wire.mode_of(mode)
        self.on_pause = on_pause
        self.stop_requested = False
        self.start_epoch: float | None = None
        self.paused = False
        self.reset_epoch: float | None = None
        self.final_received = False
        self.applied: set[tuple[str, float]] = set()  # (verb, epoch) of each pause/resume/reset
        self.replays = 0  # those that came again, not applied again

    def command(self, verb: str, epoch: float | None = None) -> Answer:
        """Apply one command; return (accepted, message for a service's caller)."""
        if epoch is not None and verb in ("pause", "resume", "reset"):
            if (verb, epoch) in self.applied:
                self.replays += 1
                return True, f"{verb} of {epoch:.3f} again, already applied: not applied twice"
            self.applied.add((verb, epoch))
        if verb == "stop":
            self.stop_requested = True
            return True, "stopping" + (" (every process at the same step)"
                                       if self.mode.exact else "")
        if verb == "received":
            self.final_received = True
            return True, "final poses received"
        if verb == "start":
            return self._start(epoch)
        if verb in ("pause", "resume"):
            self.paused = verb == "pause"
            if self.on_pause is not None:
                self.on_pause(self.paused)
            return True, "paused" if self.paused else "resumed"
        return self._reset(epoch)

    def _start(self, epoch: float | None) -> Answer:
        if self.mode.exact:
            return True, LOCKSTEP_START
        if self.start_epoch is None:
            self.start_epoch = epoch
            return True, f"t = 0 at {epoch:.3f}"
        return True, f"already started (t = 0 at {self.start_epoch:.3f})"

    def _reset(self, epoch: float | None) -> Answer:
        refusal = reset_refusal(self.mode)
        if refusal:
            return False, refusal
        self.reset_epoch = epoch
        return True, f"back to the initial state at the first tick past {epoch:.3f}"

    def take_reset(self, now: float) -> bool:
        """True once, at the first tick past the reset epoch."""
        if self.reset_epoch is None or now < self.reset_epoch:
            return False
        self.reset_epoch = None
        return True


def _trigger(handler: Callable[[], Answer]) -> Callable[[Any, Any], Any]:
    def serve(request: Any, response: Any) -> Any:
        response.success, response.message = handler()
        return response

    return serve


def _set_bool(handler: Callable[[bool], Answer]) -> Callable[[Any, Any], Any]:
    def serve(request: Any, response: Any) -> Any:
        response.success, response.message = handler(bool(request.data))
        return response

    return serve


def offer_agent_services(
    node: Node, control: AgentControl, log: RcutilsLogger, scope: str = ""
) -> list[Service]:
    """``~/start``, ``~/stop``, ``~/reset`` (Trigger) and ``~/pause`` (SetBool) of one agent
    process, applied to it alone at once; ``scope``, if given, ends each answer (a hosted
    agent's node says that its whole process applies it, ``hosted``)."""
    from std_srvs.srv import SetBool, Trigger

    def call(verb: str, epoch: float | None = None) -> Answer:
        ok, message = control.command(verb, epoch)
        log.info(f"service {verb}: {message}")
        return ok, f"{message} ({scope})" if scope else message

    return [
        node.create_service(Trigger, "~/start", _trigger(lambda: call("start", time.time()))),
        node.create_service(Trigger, "~/stop", _trigger(lambda: call("stop"))),
        node.create_service(Trigger, "~/reset", _trigger(lambda: call("reset", time.time()))),
        node.create_service(
            SetBool,
            "~/pause",
            _set_bool(lambda on: call("pause" if on else "resume", time.time())),
        ),
    ]


class EnsembleControl:
    """The ensemble-wide services, broadcast to the agents on the control topic."""

    def __init__(self, node: Node, mode: str) -> None:
        from std_srvs.srv import SetBool, Trigger

        self.node, self.mode = node, wire.mode_of(mode)
        self.log = node.get_logger()
        self.pub = wire.publisher(node, "control")
        self.epoch: float | None = None
        self.services = [
            node.create_service(Trigger, "start", _trigger(self._start)),
            node.create_service(Trigger, "stop", _trigger(self._stop)),
            node.create_service(Trigger, "reset", _trigger(self._reset)),
            node.create_service(SetBool, "pause", _set_bool(self._pause)),
        ]

    def _send(self, verb: str, epoch: float | None = None) -> None:
        msg = command_message(verb, epoch)
        self.pub.publish(msg)
        self.log.info(f"control: {describe_command(msg)}")

    def _start(self) -> Answer:
        if self.mode.exact:
            return True, LOCKSTEP_START
        again = self.epoch is not None
        if not again:
            self.epoch = time.time() + START_LEAD
        self._send("start", self.epoch)
        return True, f"{'re-sent: ' if again else ''}t = 0 at {self.epoch:.3f}"

    def _stop(self) -> Answer:
        self._send("stop")
        return True, "stop sent to every agent"

    def stop(self) -> Answer:
        """What the ``stop`` service does (the ``match`` action's cancel calls it)."""
        return self._stop()

    def _pause(self, on: bool) -> Answer:
        self._send("pause" if on else "resume", time.time())
        return True, f"{'pause' if on else 'resume'} sent to every agent"

    def _reset(self) -> Answer:
        refusal = reset_refusal(self.mode)
        if refusal:
            return False, refusal
        self._send("reset", time.time() + START_LEAD)
        return True, "reset sent: realtime agents go back to their initial state"


class ControlClient:
    """The runner's side: non-blocking calls of the ensemble's services."""

    def __init__(self, node: Node) -> None:
        from std_srvs.srv import SetBool, Trigger

        self.clients: dict[str, Client] = {
            verb: node.create_client(Trigger, verb) for verb in ("start", "stop", "reset")
        }
        self.clients["pause"] = node.create_client(SetBool, "pause")
        self.pending: list[Future] = []

    def call(self, verb: str, on: bool | None = None) -> bool:
        """Call ``verb`` if its server is up; True if the call went out (the answer is
        taken by the node's executor)."""
        client = self.clients[verb]
        if not client.service_is_ready():
            return False
        request = client.srv_type.Request()  # type: ignore[attr-defined]  # rclpy: a TypeVar
        if on is not None:
            request.data = bool(on)
        self.pending = [f for f in self.pending if not f.done()] + [client.call_async(request)]
        return True
