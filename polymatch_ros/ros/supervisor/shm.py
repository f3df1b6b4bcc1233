"""The Fast DDS shared-memory files of a run's own processes: noted while they live, removed
once they have ended.

Every process runs over UDP only (``environment.TRANSPORTS``, the loopback profile), yet under
ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST rmw_fastrtps adds a shared-memory transport of its own
to each participant, and that transport makes a segment in /dev/shm once the participant first
sends (``fastrtps_<16 hex digits>``, 512 KiB and a header) beside its lock file
(``fastrtps_<...>_el``), which the owner holds with ``flock`` while it lives.  Fast DDS removes
both when the participant is deleted; a process that is killed, or that ends before rclpy has
let go of its last node, leaves them for good.

The runner notes, by each child's open files (/proc/PID/fd), which of these its children made,
and removes them once they ended, never a segment whose lock some live process still holds
(the kernel drops a dead owner's lock).  Under a discovery beyond loopback the environment
selects the UDPv4 transport alone and nothing is made.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import time
from collections.abc import Iterable

SHM_DIR = "/dev/shm"
PREFIX = "fastrtps_"
LOCK_SUFFIX = "_el"
NOTE_INTERVAL = 0.25  # s between two looks at the children that have no segment yet


def segments_of(pid: int) -> set[str]:
    """The Fast DDS segments (names in ``SHM_DIR``, without the lock suffix) whose lock file
    process ``pid`` holds open; empty if it has ended or holds none."""
    fd_dir = f"/proc/{pid}/fd"
    try:
        fds = os.listdir(fd_dir)
    except OSError:
        return set()
    found = set()
    for fd in fds:
        with contextlib.suppress(OSError):
            target = os.readlink(os.path.join(fd_dir, fd))
            folder, name = os.path.split(target)
            if folder == SHM_DIR and name.startswith(PREFIX) and name.endswith(LOCK_SUFFIX):
                found.add(name[: -len(LOCK_SUFFIX)])
    return found


def lock_held(segment: str) -> bool:
    """True while a live process holds the segment's lock file (its owner, as Fast DDS
    itself tells a live segment from a dead one); False once no process does or the file is
    gone."""
    try:
        fd = os.open(os.path.join(SHM_DIR, segment + LOCK_SUFFIX), os.O_RDONLY)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    finally:
        os.close(fd)
    return False


class SegmentLedger:
    """The segments a run's children made (``note``), removed once unheld (``remove_ended``)."""

    def __init__(self) -> None:
        self.by_pid: dict[int, set[str]] = {}
        self.last_look = 0.0

    def note(self, pids: Iterable[int], force: bool = False) -> None:
        """Look at the given live processes that have no noted segment yet (at most every
        ``NOTE_INTERVAL`` s unless ``force``): a participant makes its segment on its first
        send, then keeps it."""
        now = time.monotonic()
        if not force and now - self.last_look < NOTE_INTERVAL:
            return
        self.last_look = now
        for pid in pids:
            if not self.by_pid.get(pid):
                self.by_pid[pid] = segments_of(pid)

    @property
    def segments(self) -> set[str]:
        return set().union(*self.by_pid.values())

    def remove_ended(self) -> list[str]:
        """Remove every noted segment no live process holds (its file and its lock file); the
        names removed.  A segment still held (a child that outlived the runner's stop) stays."""
        removed = []
        for segment in sorted(self.segments):
            if lock_held(segment):
                continue
            for name in (segment, segment + LOCK_SUFFIX):
                with contextlib.suppress(FileNotFoundError):
                    os.unlink(os.path.join(SHM_DIR, name))
            removed.append(segment)
        for pid in list(self.by_pid):
            self.by_pid[pid] -= set(removed)
        return removed
