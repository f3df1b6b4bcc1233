"""The Fast DDS files in /dev/shm that a test's own processes made, seen while they live.

Other ROS runs share the machine, so a test never counts /dev/shm as a whole: a thread looks
every ``interval`` s at the memory maps (/proc/PID/maps) of every process under the test's
processes and notes each ``/dev/shm/fastrtps_*`` segment one of them maps, with its lock file
(``<segment>_el``).  ``left()`` names those still in /dev/shm; ``remove_unheld()`` removes those
no live process holds the lock of (after a test, what its killed processes left).
"""

import contextlib
import os
import shutil
import threading

from proc_group import children

SHM = "/dev/shm/"
PREFIX = SHM + "fastrtps_"
LOCK = "_el"


def descendants(pids):
    """Every PID under the given ones (their children, grandchildren, ...), and themselves."""
    out, todo = [], list(pids)
    while todo:
        pid = todo.pop()
        out.append(pid)
        todo.extend(children(pid))
    return out


def command_line(pid):
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as fh:
            return fh.read()
    except OSError:
        return b""


def mapped_segments(pid):
    """The Fast DDS segments process ``pid`` maps (paths); empty once it has ended."""
    try:
        with open(f"/proc/{pid}/maps") as fh:
            return {line.split()[-1] for line in fh if PREFIX in line}
    except OSError:
        return set()


class ShmWatch:
    """Notes the segments of the process trees under ``roots()`` until ``stop``."""

    def __init__(self, roots, interval=0.25):
        self.roots, self.interval = roots, interval
        # (pid, command line) -> its segments' paths: a child between fork and exec still maps
        # its parent's, and is looked at again once it runs its own program
        self.seen = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._watch, daemon=True)
        self._thread.start()

    def look(self):
        for pid in descendants(self.roots()):
            key = (pid, command_line(pid))
            if not self.seen.get(key):
                self.seen[key] = mapped_segments(pid)

    def of(self, pid):
        """The segments noted of process ``pid`` (running its own program)."""
        return set().union(*[segs for (p, _), segs in list(self.seen.items()) if p == pid])

    def _watch(self):
        while not self._stop.wait(self.interval):
            self.look()

    def stop(self):
        self._stop.set()
        self._thread.join(timeout=5)

    @property
    def segments(self):
        return set().union(*list(self.seen.values()))

    def entries(self):
        """Every /dev/shm entry noted: each segment and its lock file."""
        return {path for seg in self.segments for path in (seg, seg + LOCK)}

    def left(self):
        """The noted entries still in /dev/shm."""
        return sorted(path for path in self.entries() if os.path.exists(path))

    def remove_unheld(self, wait=5.0):
        """Remove the noted segments (and lock files) whose lock no live process holds, once
        their processes (which ``close`` has ended) are gone: a segment whose lock is held is
        looked at again for up to ``wait`` s, as a SIGKILLed process holds its lock until the
        kernel has taken all its threads down, after its parent's wait has returned."""
        import time
        deadline = time.monotonic() + wait
        pending = set(self.segments)
        while pending:
            for seg in sorted(pending):
                if _remove_if_unheld(seg):
                    pending.discard(seg)
            if not pending or time.monotonic() > deadline:
                return  # what is left is held by a process that still runs: its own
            time.sleep(0.05)


def _remove_if_unheld(seg):
    """Remove segment ``seg`` and its lock file unless a process holds the lock; whether it is
    gone."""
    from polymatch_ros.ros.supervisor.shm import lock_held

    if lock_held(seg + LOCK):
        return False
    for path in (seg, seg + LOCK):
        with contextlib.suppress(FileNotFoundError):
            os.unlink(path)
    return True


def private_shm_possible():
    """Whether a process can be given a /dev/shm of its own (``private_shm_argv``): root and
    util-linux's ``unshare``."""
    return os.geteuid() == 0 and shutil.which("unshare") is not None


def private_shm_argv(argv, listing):
    """``argv`` run in a mount namespace of its own with an empty tmpfs on /dev/shm; once it has
    ended, the names left in that /dev/shm are written to the file ``listing`` (one a line) and
    its exit code is passed on.  Everything the process and its children made there is theirs
    alone: no other process on the machine can add to it or take from it."""
    script = ('mount -t tmpfs -o size=64m polymatch_shm /dev/shm || exit 97; "$@"; code=$?; '
              'ls -A /dev/shm > "$LISTING"; exit $code')
    return ["env", f"LISTING={listing}", "unshare", "--mount", "--propagation", "private",
            "sh", "-c", script, "sh", *map(str, argv)]


def fast_dds_names(listing):
    """The Fast DDS entries (segments, locks, ports) among the names of a ``listing`` file."""
    with open(listing, encoding="utf-8") as fh:
        return sorted(n for n in fh.read().split() if "fastrtps" in n or "fastdds" in n)
