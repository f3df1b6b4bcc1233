"""The runner's processes: supervised children and the partition of agents into processes
(how many agents a process hosts: ``packing``)."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import threading
import time
from collections import deque
from collections.abc import Iterable, Mapping, Sequence
from typing import TYPE_CHECKING

from ...core.errors import ParameterError
from .. import wire
from ..process import forked
from ..process.teardown import EXIT_GRACE, TEARDOWN_SECONDS, hung_in_teardown

if TYPE_CHECKING:
    from .watcher import Watcher

# A process that reported its result ends within its teardown watchdog (TEARDOWN_SECONDS +
# EXIT_GRACE); one still running this long after its final run record is ended by the runner.
OVERSTAY_SECONDS = 2 * TEARDOWN_SECONDS + EXIT_GRACE


class Child:
    """A supervised process: last lines of output kept (shown on failure); ended by its PID."""

    name: str
    restart_delay = 0.0  # its restart waits only for the policy's back-off
    stop_grace = 3.0  # SIGINT to SIGTERM when it is stopped (``stop``)
    argv: list[str]
    env: dict[str, str] | None
    agents: tuple[int, ...]
    proc: subprocess.Popen[str] | forked.ForkedProcess
    lines: deque[str]
    reported_at: float | None
    ended_by_runner: bool
    died_after_run: bool
    thread: threading.Thread

    def __init__(self, name: str, argv: Sequence[str], env: Mapping[str, str] | None,
                 agents: Sequence[int] = (), log_dir: str | None = None) -> None:
        self.name, self.argv = name, list(argv)
        self.env = None if env is None else dict(env)  # None: the runner's own
        self.agents = tuple(agents)  # the agents it hosts (none: the monitor)
        self.lines = deque(maxlen=200)
        # --logs: every line it prints, its restarts' after (line-buffered: a crash keeps them)
        self.log = (None if log_dir is None else
                    open(os.path.join(log_dir, name + ".log"), "a", buffering=1,  # noqa: SIM115
                         encoding="utf-8"))
        self._launch()

    def _launch(self) -> None:
        # a node module forked from the run's fork server (its imports done once), any
        # other command line by exec
        self.proc = forked.start(self.argv, self.env) or subprocess.Popen(
            self.argv,
            env=self.env,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL,
            text=True,
            bufsize=1,
            preexec_fn=forked.child_setup,
        )
        self.stopped_since: float | None = None  # monotonic time it was first seen stopped
        self.hung_for: float | None = None  # it hung this long and the runner ended it
        self.reported_at = None  # monotonic time its finished run record arrived
        self.ended_by_runner = False  # it reported, then overstayed, and the runner ended it
        self.died_after_run = False  # it died with its final states in (``Supervision.failure``)
        self.thread = threading.Thread(target=self._read, args=(self.proc,), daemon=True)
        self.thread.start()

    def restart(self) -> None:
        """The same command line again, in a new process (the old one has ended); its output
        follows the old one's last lines."""
        self.thread.join(timeout=1.0)
        self.lines.append(f"--- {self.name} restarted (pid {self.proc.pid} ended with code "
                          f"{self.proc.poll()}) ---")
        if self.log is not None:
            self.log.write(self.lines[-1] + "\n")
        self._launch()

    def _read(self, proc: subprocess.Popen[str] | forked.ForkedProcess) -> None:
        assert proc.stdout is not None  # a pipe: stdout=PIPE
        for line in proc.stdout:
            line = line.rstrip("\n")
            self.lines.append(line)
            if self.log is not None:
                self.log.write(f"[{time.time():.3f}] {line}\n")
            if self.reported_at is None and line.startswith("{"):
                rec = wire.RunRecord.from_json(line)
                if rec is not None and rec.finished:
                    self.reported_at = time.monotonic()

    @property
    def pid(self) -> int:
        return self.proc.pid

    def poll(self) -> int | None:
        return self.proc.poll()

    def stop(self, grace: float | None = None) -> int | None:
        """SIGINT, then SIGTERM (after ``grace``, default ``stop_grace`` s), then SIGKILL — each
        to this child's PID only."""
        grace = self.stop_grace if grace is None else grace
        for sig, wait in ((signal.SIGINT, grace), (signal.SIGTERM, 2.0), (signal.SIGKILL, 2.0)):
            if self.proc.poll() is not None:
                break
            try:
                os.kill(self.proc.pid, sig)
            except ProcessLookupError:
                break
            try:
                self.proc.wait(timeout=wait)
            except subprocess.TimeoutExpired:
                continue
        # its last lines (the run record) may still be in the pipe: once the process has
        # ended, the reader reaches EOF at once unless a loaded machine starves it
        self.thread.join(timeout=5.0 if self.proc.poll() is not None else 1.0)
        return self.proc.poll()

    def tail(self, n: int = 5) -> list[str]:
        return list(self.lines)[-n:]

    def stopped_for(self) -> float:
        """Seconds this process has been stopped (``kill -STOP``, a debugger), 0 if it runs;
        from its state in /proc, sampled on each call."""
        try:
            with open(f"/proc/{self.proc.pid}/stat") as fh:
                state = fh.read().rsplit(")", 1)[1].split()[0]
        except (OSError, IndexError):
            state = ""
        if state not in ("T", "t"):
            self.stopped_since = None
            return 0.0
        now = time.monotonic()
        self.stopped_since = now if self.stopped_since is None else self.stopped_since
        return now - self.stopped_since

    def end_hung(self) -> None:
        """End a process that hangs, by its PID (SIGKILL: a stopped process takes no other
        signal); it then dies as any other and the restart policy takes it."""
        self.hung_for = self.stopped_for()
        with contextlib.suppress(ProcessLookupError):
            os.kill(self.proc.pid, signal.SIGKILL)

    def hung_in_teardown(self) -> bool:
        """Reported its final line, then its DDS teardown hung and its watchdog (or, past
        ``OVERSTAY_SECONDS``, the runner) ended it."""
        return self.ended_by_runner or bool(hung_in_teardown(self.proc.poll(), list(self.lines)))

    def ended_well(self) -> bool:
        code = self.proc.poll()
        return code == 0 or (code is not None and (self.died_after_run or self.hung_in_teardown()))

    def end_if_overstaying(self, seconds: float) -> bool:
        """A process that printed its finished run record and is still running ``seconds``
        later is stuck in its teardown (its own watchdog did not end it): end it by its PID.
        Its result is in; True if it was ended here."""
        if self.reported_at is None or self.proc.poll() is not None:
            return False
        if time.monotonic() - self.reported_at < seconds:
            return False
        self.ended_by_runner = True
        self.stop(grace=1.0)
        return True

    def records(self) -> list[wire.RunRecord]:
        """The run records this child printed (``wire.run_records``)."""
        return wire.run_records(list(self.lines))


def partition(agents: int | Iterable[int], k: int) -> list[list[int]]:
    """The agents (a count, or a list of indices) in consecutive processes of at most ``k``."""
    chosen = list(range(agents)) if isinstance(agents, int) else list(agents)
    return [chosen[s : s + k] for s in range(0, len(chosen), k)]


def parse_only(text: str | None, n_agents: int) -> list[int]:
    """``--only 0-7,12`` -> the sorted agent indices it names, each in 0..n_agents-1.

    Raises ParameterError (one line) for anything else.
    """
    spec = (text or "").strip()
    chosen: set[int] = set()
    for part in spec.split(","):
        first, dash, last = (piece.strip() for piece in part.partition("-"))
        if not _index(first) or (dash and not _index(last)):
            raise ParameterError(
                f"--only {spec!r}: list agent indices and ranges, e.g. --only 0-7,12"
            )
        low, high = int(first), int(last) if dash else int(first)
        if low > high:
            raise ParameterError(f"--only {spec!r}: the range {part.strip()} runs backwards")
        if high >= n_agents:
            raise ParameterError(
                f"--only {spec!r}: agent {high} is not in 0..{n_agents - 1} "
                f"(the scene has {n_agents} agents)"
            )
        chosen.update(range(low, high + 1))
    return sorted(chosen)


def _index(text: str) -> bool:
    return text.isascii() and text.isdigit()


def describe_agents(agents: Sequence[int]) -> str:
    """[0, 1, 2, 3, 12] -> '0-3,12' (the --only form)."""
    runs: list[str] = []
    start: int | None = None
    for position, agent in enumerate(agents):
        start = agent if start is None else start
        if position + 1 == len(agents) or agents[position + 1] != agent + 1:
            runs.append(f"{start}" if start == agent else f"{start}-{agent}")
            start = None
    return ",".join(runs)


MONITOR_GRACE_SECONDS = 10.0
# How long the watcher listens for the monitor's last reports once the agents are ended, unless
# the monitor has already reported the final step with every agent (a lockstep run's end) and no
# recorder is to hear them too
LAST_REPORTS_SECONDS = 0.5


def stop_all(children: Sequence[Child], monitor: Child | None, watcher: Watcher | None,
             recorded: bool = False) -> None:
    """End every child by its PID; the monitor last, after the watcher (and the recorder of a
    ``recorded`` run) heard its last reports."""
    for c in children:
        c.stop()
    if monitor is not None:
        t0 = time.monotonic()
        while (watcher is not None and time.monotonic() - t0 < LAST_REPORTS_SECONDS
               and (recorded or not watcher.monitor_reported_final())):
            watcher.spin(0.05)
        # its final record is the summary's monitor line: on a loaded machine (or under a
        # flood of rogue messages) it can take more than the agents' 3 s to write it
        monitor.stop(grace=MONITOR_GRACE_SECONDS)
