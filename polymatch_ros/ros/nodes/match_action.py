"""The ``/<ensemble>/match`` action (``polymatch_interfaces/action/Match``), served by the monitor.

A goal waits until the ensemble matches: its matching diameter falls below the goal's
tolerance (0: the scene's).  At each of the monitor's reports every goal gets feedback (the
simulated time, the three diameters, the agents heard, the certificate's state) and ends when
its diameter is below the tolerance (``matched``), when ``time_limit`` simulated seconds have
passed since it was accepted (``time limit``), or when the monitor ends (``run ended``).
Cancelling a goal stops the ensemble as ``/<ensemble>/stop`` does (``control``): every agent
ends, lockstep agents at the same step, and ``polymatch run`` exits 4.

    ros2 action send_goal --feedback /polymatch/match polymatch_interfaces/action/Match \\
        "{tolerance: 1.0e-6, time_limit: 0.0}"

A goal is accepted and then advanced by the reports; only once it is decided does its execute
callback run (``_finish``), at once: no goal waits in the monitor's executor, whose loop
stays the monitor's own (an awaiting coroutine is resumed at every turn of rclpy's executor).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from rclpy.action.server import ServerGoalHandle
    from rclpy.executors import Executor
    from rclpy.node import Node

    from ...core.certificate import CertificateKeeper
    from ...core.metrics import EnsembleMetrics
    from ..wire.control import EnsembleControl

#: how long the monitor, once stopped, serves the goals' results (wall-clock seconds)
RESULT_SECONDS = 2.0


def certificate_state(keeper: CertificateKeeper) -> str:
    """'granted', 'refused' or 'pending' (nothing evaluated yet) of the run's certificate."""
    if keeper.current is None:
        return "pending"
    return "granted" if keeper.current.certified else "refused"


@dataclass
class Report:
    """One of the monitor's reports, as the goals see it."""

    t: float
    diameter: float
    diameter_centroid: float
    diameter_rotation: float
    agents_heard: int
    certificate: str


@dataclass
class Pursuit:
    """One accepted goal: its tolerance, its deadline (simulated s), the report it waits for."""

    handle: ServerGoalHandle
    tolerance: float
    deadline: float                      # simulated time; inf: until the run ends
    below_since: float = math.nan        # the first report of the current streak below
    ended: tuple[bool, str] | None = None  # (matched, reason) once decided
    final: Report | None = None            # the last report when it was decided


class MatchServer:
    """The action server of one ensemble (in the monitor's namespace)."""

    def __init__(self, node: Node, tolerance: float, n_agents: int,
                 control: EnsembleControl) -> None:
        from rclpy.action import ActionServer

        from polymatch_interfaces.action import Match

        self.node, self.tolerance, self.n_agents, self.control = node, tolerance, n_agents, control
        self.log = node.get_logger()
        self.last: Report | None = None
        self.pursuits: list[Pursuit] = []
        self.server = ActionServer(
            node, Match, "match", self._finish, goal_callback=self._check_goal,
            handle_accepted_callback=self._accepted, cancel_callback=self._cancel,
        )

    def _check_goal(self, goal: Any) -> Any:
        from rclpy.action import GoalResponse

        for name in ("tolerance", "time_limit"):
            value = getattr(goal, name)
            if not (math.isfinite(value) and value >= 0.0):
                self.log.warning(f"match goal refused: {name} must be finite and >= 0, "
                                 f"got {value!r}")
                return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def _cancel(self, handle: ServerGoalHandle) -> Any:
        """Accept the cancel and stop the ensemble (the ``stop`` service's broadcast)."""
        from rclpy.action import CancelResponse

        for pursuit in self.pursuits:
            if pursuit.handle is handle and pursuit.ended is None:
                self.control.stop()
                self._end(pursuit, False, "canceled")
        return CancelResponse.ACCEPT

    def _accepted(self, handle: ServerGoalHandle) -> None:
        """A goal to pursue: the reports advance it (``_advance``) until it is decided."""
        goal = handle.request
        now = self.last.t if self.last is not None else 0.0
        pursuit = Pursuit(handle, goal.tolerance or self.tolerance,
                          now + goal.time_limit if goal.time_limit > 0.0 else math.inf)
        self.pursuits.append(pursuit)
        self.log.info(f"match goal: diameter below {pursuit.tolerance:g}"
                      + (f" by t = {pursuit.deadline:g}" if goal.time_limit > 0.0 else ""))
        if self.last is not None:
            self._advance(pursuit, self.last)

    def _finish(self, handle: ServerGoalHandle) -> Any:
        """The execute callback, called once a goal is decided (``_end``): its result."""
        from action_msgs.msg import GoalStatus

        from polymatch_interfaces.action import Match

        pursuit = next(p for p in self.pursuits if p.handle is handle)
        self.pursuits.remove(pursuit)
        matched, reason = pursuit.ended or (False, "run ended")
        last = pursuit.final
        result = Match.Result(
            matched=matched, reason=reason,
            matched_at=pursuit.below_since if matched else math.nan,
            diameter=math.nan if last is None else last.diameter,
        )
        if handle.is_cancel_requested:
            handle.canceled()
        elif matched:
            handle.succeed()
        else:
            handle.abort()
        status = {GoalStatus.STATUS_SUCCEEDED: "succeeded", GoalStatus.STATUS_ABORTED: "aborted",
                  GoalStatus.STATUS_CANCELED: "canceled"}.get(handle.status, str(handle.status))
        self.log.info(f"match goal {status}: {reason}, diameter {result.diameter:.3e}")
        return result

    def report(self, t: float, met: EnsembleMetrics, heard: int,
               keeper: CertificateKeeper) -> None:
        """A report of the monitor: feedback to every goal, and the goals it decides end."""
        self.last = Report(
            t=float(t), diameter=float(met.diameter),
            diameter_centroid=float(max(g.centroid_diameter for g in met.groups)),
            diameter_rotation=float(max(g.rotation_diameter for g in met.groups)),
            agents_heard=heard, certificate=certificate_state(keeper),
        )
        for pursuit in list(self.pursuits):
            if pursuit.ended is None:
                self._advance(pursuit, self.last)

    def _advance(self, pursuit: Pursuit, rep: Report) -> None:
        from polymatch_interfaces.action import Match

        pursuit.handle.publish_feedback(Match.Feedback(
            t=rep.t, diameter=rep.diameter, diameter_centroid=rep.diameter_centroid,
            diameter_rotation=rep.diameter_rotation, agents_heard=rep.agents_heard,
            n_agents=self.n_agents, certificate=rep.certificate,
        ))
        below = rep.agents_heard == self.n_agents and rep.diameter < pursuit.tolerance
        if not below:
            pursuit.below_since = math.nan
        elif math.isnan(pursuit.below_since):
            pursuit.below_since = rep.t
        if below:
            self._end(pursuit, True, "matched")
        elif rep.t >= pursuit.deadline:
            self._end(pursuit, False, "time limit")

    def _end(self, pursuit: Pursuit, matched: bool, reason: str) -> None:
        """Decide a goal: its execute callback (``_finish``) runs at the executor's next turn."""
        if pursuit.ended is None:
            pursuit.ended, pursuit.final = (matched, reason), self.last
            pursuit.handle.execute()

    def close(self, executor: Executor) -> None:
        """The monitor ends: every open goal ends (``run ended``; ``matched`` if its diameter
        is below its tolerance), and the executor serves their results for at most
        ``RESULT_SECONDS`` (until the clients that asked for them have them)."""
        for pursuit in list(self.pursuits):
            if pursuit.ended is None:
                rep = self.last
                below = (rep is not None and rep.agents_heard == self.n_agents
                         and rep.diameter < pursuit.tolerance)
                self._end(pursuit, below, "matched" if below else "run ended")
        if not self.pursuits and not self._results_pending():
            return  # no goal to answer: the monitor's end is not delayed
        deadline = time.monotonic() + RESULT_SECONDS
        settled = 0  # turns with nothing left: the results' responses go out in later tasks
        while time.monotonic() < deadline and settled < 5:
            executor.spin_once(timeout_sec=0.02)
            settled = 0 if self.pursuits or self._results_pending() else settled + 1

    def _results_pending(self) -> bool:
        """A goal's result that a client asked for and has not been sent yet."""
        futures = getattr(self.server, "_result_futures", {})
        return any(not f.done() for f in futures.values())

    def destroy(self) -> None:
        self.server.destroy()
