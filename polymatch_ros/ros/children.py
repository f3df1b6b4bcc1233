"""The runner's processes: supervised children, the partition of agents into processes, and
the DDS participant limit of LOCALHOST discovery."""

import os
import signal
import subprocess
import sys
import threading
import time
from collections import deque

from ..core.errors import PolymatchError
from . import wire
from .ros_env import hung_in_teardown


def _die_with_parent():
    """In the child, before exec: SIGTERM when the runner dies (Linux): nothing outlives it."""
    try:
        import ctypes

        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


class Child:
    """A supervised process: last lines of output kept (shown on failure); ended by its PID."""

    def __init__(self, name, argv, env):
        self.name = name
        self.proc = subprocess.Popen(
            argv,
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL,
            start_new_session=True,
            text=True,
            bufsize=1,
            preexec_fn=_die_with_parent,
        )
        self.lines = deque(maxlen=200)
        self.thread = threading.Thread(target=self._read, daemon=True)
        self.thread.start()

    def _read(self):
        for line in self.proc.stdout:
            self.lines.append(line.rstrip("\n"))

    @property
    def pid(self):
        return self.proc.pid

    def poll(self):
        return self.proc.poll()

    def stop(self, grace=3.0):
        """SIGINT, then SIGTERM, then SIGKILL — each to this child's PID only."""
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
        self.thread.join(timeout=1.0)
        return self.proc.poll()

    def tail(self, n=5):
        return list(self.lines)[-n:]

    def hung_in_teardown(self):
        """Reported its final line, then its DDS teardown hung and its watchdog ended it."""
        return hung_in_teardown(self.proc.poll(), list(self.lines))

    def ended_well(self):
        return self.proc.poll() == 0 or self.hung_in_teardown()

    def records(self):
        """The run records this child printed (``wire.run_records``)."""
        return wire.run_records(list(self.lines))


def partition(n_agents, k):
    return [list(range(s, min(s + k, n_agents))) for s in range(0, n_agents, k)]


# rmw_fastrtps, under ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST, probes the first 32 participant
# ports on 127.0.0.1 (its UDP maxInitialPeersRange): two participants beyond that never meet.
LOCALHOST_PARTICIPANTS = 32


def fewest_agents_per_process(n_agents, own):
    """Agents per process that keep ``own`` + the agent processes within LOCALHOST_PARTICIPANTS."""
    return -(-n_agents // (LOCALHOST_PARTICIPANTS - own))


def _agents_per_process(args, n_agents, localhost):
    """-k as given (checked against the participant limit), else 1 if it fits, else the fewest."""
    own = 1 + (1 if args.monitor else 0)  # the runner's node, the monitor
    need = fewest_agents_per_process(n_agents, own)
    if args.agents_per_process is None:
        if localhost and need > 1:
            if not args.quiet:
                print(
                    f"polymatch run: {n_agents} agents + {own} own processes exceed the "
                    f"{LOCALHOST_PARTICIPANTS} DDS participants LOCALHOST discovery reaches: "
                    f"{need} agents per process (-k {need})",
                    file=sys.stderr,
                )
            return need
        return 1
    procs = -(-n_agents // args.agents_per_process)
    if localhost and procs + own > LOCALHOST_PARTICIPANTS:
        raise PolymatchError(
            f"{procs} agent processes + {own} own = {procs + own} DDS participants, but LOCALHOST "
            f"discovery reaches {LOCALHOST_PARTICIPANTS} per domain (rmw_fastrtps' initial-peer "
            f"range); use -k {need} or more"
        )
    return args.agents_per_process


def stop_all(children, monitor, watcher):
    """End every child by its PID; the monitor last, after the watcher heard its last reports."""
    for c in children:
        c.stop()
    if monitor is not None:
        t0 = time.monotonic()
        while watcher is not None and time.monotonic() - t0 < 0.5:
            watcher.spin(0.05)
        monitor.stop()
