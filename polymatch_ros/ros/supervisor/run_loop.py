"""The runner's main loop (``Supervision``): progress, the realtime start, the stop on
convergence, the failures and restarts of its children, the wait for the final poses.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import TYPE_CHECKING

from ...console import Progress
from .children import OVERSTAY_SECONDS, Child, describe_agents
from .plan import RunPlan
from .recovery import Recovery

if TYPE_CHECKING:
    from ..network.discovery import DiscoveryServer
    from .lifecycle_driver import LifecycleDriver
    from .watcher import Watcher

# How long the host that prints the summary waits, after its own agents ended, for the latched
# final poses: of its own agents (in flight), of the agents on other hosts (still finishing).
FINAL_POSE_SECONDS = 3.0
REMOTE_FINAL_POSE_SECONDS = 30.0


class Supervision:
    """The runner's loop: progress, start (realtime), stop on convergence, failures, the end.

    ``plan.hosts.lead`` (this host runs the monitor or every agent) starts a realtime ensemble
    and waits for the final poses of all agents; ``plan.hosts.agents`` are this host's agents.
    """

    plan: RunPlan
    watcher: Watcher
    children: list[Child]
    monitor: Child | None
    server: DiscoveryServer | None   # this run's own discovery server (``--discovery server``)
    progress: Progress
    rounds_per_step: int
    rate_mark: tuple[float, float] | None  # (wall clock, ensemble time) the rate counts from
    rps: float
    below_since: float | None
    stop_sent: float
    graph_checked: bool
    started: bool
    start_sent: float
    received_sent: bool

    def __init__(self, plan: RunPlan, watcher: Watcher, children: list[Child],
                 monitor: Child | None, progress: Progress,
                 server: DiscoveryServer | None = None,
                 others: Sequence[Child] = ()) -> None:
        self.plan, self.watcher, self.progress = plan, watcher, progress
        self.children, self.monitor, self.server = children, monitor, server
        self.others = list(others)  # bridge mode's robots, the recorder
        self.rounds_per_step = (
            1 if plan.realtime else max(1, plan.numerics.method.info.rounds)
        )
        self.rate_mark, self.rps = None, 0.0
        self.below_since, self.stop_sent = None, 0.0
        self.graph_checked = False
        self.started, self.start_sent, self.received_sent = False, 0.0, False
        self.recovery = Recovery(plan.on_failure)
        self.lifecycles: list[LifecycleDriver] = []
        self.returning: list[Child] = []  # restarted, not heard from yet

    def processes(self) -> list[Child | DiscoveryServer]:
        """The agent processes, then the monitor and the discovery server (if any)."""
        extra = [p for p in (self.monitor, self.server) if p is not None]
        return [*self.children, *extra]

    def failure(self) -> tuple[int, str] | None:
        """The run's end by a dead process, as (code, message), or None: under the restart
        policy a process that died is started again after its back-off (``recovery``)."""
        for c in self.processes():
            # poll first: a child that exits between "not ended well" (still running) and "has
            # ended" would be taken for a failure with exit code 0
            if c.poll() is None or c.ended_well() or self.recovery.pending(c):
                continue
            if self.done_before_death(c):
                continue
            error = self.recovery.died(c, self.watcher.ensemble_time())
            if error is not None:
                return 1, error
        for c in self.recovery.restart_due(self.processes()):
            self.rejoin(c)
        self.end_hung()
        return None

    def done_before_death(self, child: Child | DiscoveryServer) -> bool:
        """An agent process that died after its run had ended, nothing of it needed again: its
        agents' final states are here and, in lockstep, every agent's (each has then ended its
        last round, so no peer waits for a message of the dead one).  It is listed among the
        failures, not restarted.  A lockstep process that died before every final state came
        is restarted: it replays its last step with its peers (``LockstepAgent.settle``)."""
        if not isinstance(child, Child) or child is self.monitor or not child.agents:
            return False
        done = (self.watcher.have_final_of(child.agents) if self.plan.realtime
                else self.watcher.have_final())
        if done:
            child.died_after_run = True
            self.recovery.ended(child, min(self.watcher.poses[a][0] for a in child.agents))
        return done

    def end_hung(self) -> None:
        """Lockstep under ``--on-failure restart``: a process stopped for longer than the round
        timeout is taken for dead (every round waits for it): ended, then restarted and resumed.
        Realtime peers go on without a hung process and take it back when it resumes."""
        if self.plan.realtime or not self.plan.on_failure.restart:
            return
        for c in self.children:
            if c.poll() is None and c.stopped_for() > self.plan.timing.round_timeout:
                c.end_hung()

    def rejoin(self, child: Child | DiscoveryServer) -> None:
        """A restarted process: forget the dead one's reports, drive the new one's lifecycle
        (agents); realtime agents get the ensemble's start again (``start_clock``).  The
        discovery server is back once it listens (``DiscoveryServer.launch``)."""
        if not isinstance(child, Child):
            self.recovery.heard_again(child.name)
            return
        if child is self.monitor:
            self.watcher.monitor = None
        else:
            self.watcher.agents.pop(child.agents, None)
            self.lifecycles.append(self.watcher.drive_lifecycle(
                [child.name], lambda name: " | ".join(child.tail(2)).strip()))
        self.returning.append(child)

    def note_returns(self) -> None:
        """Restarted processes heard again: the monitor's report, an agent's run record."""
        for child in list(self.returning):
            if child is self.monitor:
                heard, resumed_at = self.watcher.monitor is not None, None
            else:
                record = self.watcher.agents.get(child.agents)
                heard = record is not None
                resumed_at = record.resumed_at if record is not None else None
            if heard:
                self.recovery.heard_again(child.name, resumed_at)
                self.returning.remove(child)

    def last_words(self, most: int = 3) -> str:
        """'; <process>: <its last line>' for up to ``most`` processes still running: what they
        were doing when the run timed out (a lockstep agent says which peers it waits for)."""
        running = [c for c in self.children if c.poll() is None and c.tail(1)]
        return "".join(f"; {c.name}: {c.tail(1)[0].strip()}" for c in running[:most])

    def check_graph(self) -> None:
        """Once every agent is up: its node and the monitor are in the ensemble's namespace."""
        if self.graph_checked or not self.watcher.agents_up():
            return
        names = [c.name for c in self.children] + (["monitor"] if self.monitor is not None else [])
        restarted = {f.process for f in self.recovery.failures}
        self.graph_checked = self.watcher.check_graph(names, restarted)

    def start_clock(self) -> None:
        """Realtime: once every agent is up, call the ensemble's ``start`` service (t = 0 on every
        agent ``control.START_LEAD`` s later); again each second while an agent has not begun
        stepping - the service re-sends the same epoch to one whose control reader matched late
        (agents take the first start only)."""
        now = time.monotonic()
        if not self.watcher.agents_up() or now - self.start_sent <= 1.0:
            return
        waiting = any(r.steps == 0 and not r.finished for r in self.watcher.agents.values())
        if (waiting or not self.started) and self.watcher.start():
            self.started, self.start_sent = True, now

    def watch(self, interrupted: Sequence[int], start: float) -> tuple[int, str]:
        """Until the run ends: (exit code, error message or "")."""
        watcher, plan = self.watcher, self.plan
        lead, timeout = plan.hosts.lead, plan.timing.timeout
        self.started, self.start_sent, self.received_sent = False, 0.0, False
        by_name = {c.name: c for c in self.children}
        self.lifecycles = [watcher.drive_lifecycle(
            list(by_name), lambda name: " | ".join(by_name[name].tail(2)).strip()
        )]
        while True:
            watcher.spin(0.05)
            for lifecycle in self.lifecycles:
                lifecycle.step()
            self.lifecycles = [d for d in self.lifecycles if not d.active()]
            self.note_returns()
            if plan.realtime and lead:
                self.start_clock()
            self.check_graph()
            if interrupted:
                self.progress.done()
                return 130, "interrupted: stopped every process"
            failed = self.failure()
            if failed:
                self.progress.done()
                return failed
            for c in self.children:
                c.end_if_overstaying(OVERSTAY_SECONDS)
            if lead and not self.received_sent and self.final_everywhere():
                watcher.received()  # the agents hold their final poses until this
                self.received_sent = True
            if all(c.ended_well() for c in self.children):
                return self.await_final_poses()
            if time.monotonic() > start + timeout:
                self.progress.done()
                last = self.last_words()
                return 1, f"timed out after {timeout:g} s (raise --timeout){last}"
            self.show_progress()

    def final_everywhere(self) -> bool:
        """Every final pose is here and, in lockstep, the monitor (if any) has reported the
        final step with every agent: nobody needs another message from the agents.  After a
        process died with its run done (``done_before_death``) the monitor may never hear
        its final step: the final poses are enough."""
        if not self.watcher.have_final():
            return False
        if self.plan.realtime or self.monitor is None:
            return True
        if any(c.died_after_run for c in self.children):
            return True
        return self.watcher.monitor_reported_final()

    def await_final_poses(self) -> tuple[int, str]:
        """(0, "") once the lead host has every agent's final pose (other hosts: at once)."""
        if not self.plan.hosts.lead:
            return 0, ""
        remote = not self.plan.every_agent_here
        seconds = REMOTE_FINAL_POSE_SECONDS if remote else FINAL_POSE_SECONDS
        drain = time.monotonic() + seconds
        while time.monotonic() < drain and not self.watcher.have_final():
            self.watcher.spin(0.05)
        if self.watcher.have_final() and not self.received_sent:
            self.watcher.received()  # the other hosts' agents may end now
        if not self.watcher.have_final():  # no summary from a partial state: an error
            missing = sorted(set(range(self.plan.n_agents)) - set(self.watcher.poses))
            drops = self.watcher.final_drops
            dropped = "".join(f"; dropped {n} final state(s): {why}" for why, n in drops.items())
            return 1, (
                f"no final pose from agents {describe_agents(missing) or '(velocities)'} "
                f"within {seconds:g} s after the agents of this host ended{dropped}"
            )
        return 0, ""

    def show_progress(self) -> None:
        t, d = self.watcher.ensemble_time(), self.watcher.diameter
        if t is None or d is None:
            return
        now = time.monotonic()
        if self.rate_mark is None or t < self.rate_mark[1]:
            self.rate_mark = (now, t)  # (re)start the rate where the ensemble's time is
        elif now - self.rate_mark[0] > 1.0:
            steps = (t - self.rate_mark[1]) / max(self.plan.numerics.dt or 0.0, 1e-12)
            self.rps = steps * self.rounds_per_step / (now - self.rate_mark[0])
            self.rate_mark = (now, t)
        self.progress(t, d, f"  {self.rps:7.1f} rounds/s")
        if d < self.plan.scene.tolerance and self.watcher.all_heard():
            self.below_since = t if self.below_since is None else self.below_since
            if t - self.below_since >= self.plan.timing.hold and now - self.stop_sent > 0.5:
                self.watcher.stop()
                self.stop_sent = now
        else:
            self.below_since = None
