"""When a process of a run dies: the restart policy (``--on-failure``) and the run's failures.

``restart`` (the default) starts a process that died (a signal, a crash) again with the same
command line after a short back-off, as ``respawn`` does in ROS 2 launch; a process that dies
``most`` times within ``window`` seconds ends the run with one line naming it.  What the
restarted process does depends on the mode:

- lockstep: it resumes from its checkpoint at the start of its last step, and its peers, who
  waited for it, replay that step's rounds with it (``wire.checkpoint``): the trajectory is
  the uninterrupted one, so the run still equals the centralised simulation.
- realtime and bridge: it rejoins the ensemble's clock at its current tick from its initial
  state (``RealtimeAgent._join_clock``), as a peer back from a lost link does; a bridge agent
  takes its robot's measured pose.  Its peers dropped it after ``peer_timeout`` and take it back.
- the monitor: restarted; no agent waits for it, and its reports resume.

A process that ends with an error of its own (``agent: error: ...``: a bad parameter, a
discovery that timed out) refused to run; starting it again would refuse again, so that ends
the run under either policy.  ``stop`` ends the run at the first failure, as before.
"""

from __future__ import annotations

import json
import signal
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Protocol, TypeVar

POLICIES = ("restart", "stop")
FAILURE_KEY = "polymatch_failure"
#: what a process that ended with an error of its own printed (``process.shell.ros_main``)
OWN_ERRORS = ("agent: error: ", "monitor: error: ")


class Process(Protocol):
    """What the policy needs of a supervised process (``children.Child``)."""

    name: str

    @property
    def hung_for(self) -> float | None:
        """It hung this long and the runner ended it (None: it died)."""

    @property
    def restart_delay(self) -> float:
        """The least back-off before its restart."""

    @property
    def pid(self) -> int: ...

    def poll(self) -> int | None: ...

    def tail(self, n: int = 5) -> list[str]: ...

    def restart(self) -> None: ...


P = TypeVar("P", bound=Process)


@dataclass(frozen=True)
class RestartPolicy:
    """``--on-failure``: restart dead processes (at most ``most`` deaths of one process within
    ``window`` s, each after ``backoff`` s, doubled per recent death) or stop the run."""

    restart: bool = True
    most: int = 3
    window: float = 30.0
    backoff: float = 0.5


@dataclass
class Failure:
    """One death of a process: when, how, and how long until it was back."""

    process: str
    pid: int
    code: int                   # exit code; negative: killed by that signal
    t: float | None             # the ensemble's simulated time when it was noticed
    last_line: str
    died: float                 # monotonic time it was noticed
    restarted: float | None = None    # monotonic time its new process started
    back: float | None = None         # monotonic time the new process was heard again
    new_pid: int | None = None
    resumed_at: int | None = None     # lockstep: the step the new process resumed at
    hung_for: float | None = None     # it hung (stopped) this long before the runner ended it
    after_run: bool = False           # it died with its run done: not restarted (``ended``)

    def how(self) -> str:
        """'killed by SIGKILL' or 'exit code 1'."""
        if self.code < 0:
            try:
                return f"killed by {signal.Signals(-self.code).name}"
            except ValueError:
                return f"killed by signal {-self.code}"
        return f"exit code {self.code}"

    def describe(self) -> str:
        """The summary's line for people."""
        when = "before the ensemble's clock started" if self.t is None else f"at t = {self.t:.4g}"
        how = (self.how() if self.hung_for is None else
               f"hung (stopped) for {self.hung_for:.1f} s, ended by the runner")
        text = f"{self.process} (pid {self.pid}) {how} {when}"
        if self.after_run:
            return text + " after its run had ended, its final states in; not restarted"
        if self.restarted is None:
            return text + "; not restarted"
        text += f"; restarted after {self.restarted - self.died:.1f} s as pid {self.new_pid}"
        if self.back is None:
            return text + ", not heard from again"
        text += f", back after {self.back - self.died:.1f} s"
        if self.resumed_at is not None:
            text += f", resumed at step {self.resumed_at}"
        return text

    def to_json(self) -> str:
        """One line of ``--run-records`` (record readers skip it: ``wire.run_records``)."""
        data = asdict(self)
        for key in ("restarted", "back"):
            value = data.pop(key)
            data[f"{key}_after"] = None if value is None else value - self.died
        data.pop("died")
        return json.dumps({FAILURE_KEY: 1, **data})


def own_error(child: Process) -> str | None:
    """The error line of a process that refused to run, or None (it died)."""
    for line in reversed(child.tail(5)):
        if line.startswith(OWN_ERRORS):
            return line
    return None


class Recovery:
    """The runner's bookkeeping of deaths and restarts under a ``RestartPolicy``."""

    def __init__(self, policy: RestartPolicy) -> None:
        self.policy = policy
        self.failures: list[Failure] = []
        self.due: dict[str, float] = {}  # process name -> monotonic time of its restart

    def died(self, child: Process, t: float | None) -> str | None:
        """Take note of a dead ``child``; None if it is to be restarted, else the run's error."""
        now, code = time.monotonic(), child.poll()
        assert code is not None  # it ended
        last = " | ".join(line for line in child.tail(3) if line.strip())
        failure = Failure(child.name, child.pid, code, t, last, now,
                          hung_for=child.hung_for)
        self.failures.append(failure)
        refused = own_error(child)
        if refused is not None or not self.policy.restart:
            return f"{child.name} (pid {child.pid}) exited with code {code}: {last}"
        recent = [f for f in self.failures
                  if f.process == child.name and now - f.died <= self.policy.window]
        if len(recent) >= self.policy.most:
            return (f"{child.name} died {len(recent)} times within {self.policy.window:g} s "
                    f"(last: {failure.how()}), not restarted again: {last or 'no output'}")
        backoff = self.policy.backoff * 2 ** (len(recent) - 1)
        self.due[child.name] = now + max(backoff, child.restart_delay)
        return None

    def ended(self, child: Process, t: float | None) -> None:
        """Take note of a ``child`` that died after its run had ended, with its final states
        in the runner's hands: nothing of it is needed again, so it is not restarted (a
        restarted one would begin a run its peers have ended)."""
        last = " | ".join(line for line in child.tail(3) if line.strip())
        self.failures.append(Failure(child.name, child.pid, child.poll() or 0, t, last,
                                     time.monotonic(), after_run=True))

    def pending(self, child: Process) -> bool:
        """A restart of ``child`` is due (it is dead and will be started again)."""
        return child.name in self.due

    def restart_due(self, children: Sequence[P]) -> list[P]:
        """Start again every child whose back-off has passed; those restarted."""
        now = time.monotonic()
        started = []
        for child in children:
            if self.due.get(child.name, float("inf")) <= now:
                del self.due[child.name]
                child.restart()
                failure = self.last_failure(child.name)
                failure.restarted, failure.new_pid = now, child.pid
                started.append(child)
        return started

    def last_failure(self, name: str) -> Failure:
        return [f for f in self.failures if f.process == name][-1]

    def heard_again(self, name: str, resumed_at: int | None = None) -> None:
        """The restarted ``name`` was heard (its first run record; lockstep: the step it
        resumed at)."""
        failure = self.last_failure(name)
        if failure.restarted is not None and failure.back is None:
            failure.back, failure.resumed_at = time.monotonic(), resumed_at
