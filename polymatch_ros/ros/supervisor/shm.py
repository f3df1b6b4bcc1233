"""The Fast DDS shared-memory files that processes which died during a run left in /dev/shm,
removed once the run ends.

Every process runs over UDP only (``environment.TRANSPORTS``, the loopback profile), yet under
ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST rmw_fastrtps adds a shared-memory transport of its own
to each participant, and that transport makes a segment in /dev/shm once the participant first
sends (``fastrtps_<16 letters or digits>``, 512 KiB and a header) beside its lock file
(``<segment>_el``).  A participant that listens on shared memory (one started without the
profile) also makes its ports (``fastrtps_port<N>``, with ``_el`` or ``_sl`` and
``sem.fastrtps_port<N>_mutex``).  Fast DDS removes them when the participant is deleted; a
process that is killed, or that ends before rclpy has let go of its last node, leaves them.

Fast DDS tells a dead owner's files from a live one's by the lock files: the owner holds them
with ``flock`` while it lives, the kernel drops the lock when it dies, and ``fastdds shm clean``
removes the files whose locks no process holds.  ``ShmSweep`` applies that rule to the files
that appeared in /dev/shm while the run lasted: what the run's killed children left, and what
any other process that died meanwhile left; never a file that was there before the run, nor one
whose owner lives.  No look at the children while they run is needed, so none is missed (a
child killed right after its first send).
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import re
import time

SHM_DIR = "/dev/shm"
LOCK_SUFFIXES = ("_el", "_sl")
#: the names ``fastdds shm clean`` takes for a participant's segment and a port
SEGMENT = re.compile(r"fastrtps_[0-9a-z]{16}")
PORT = re.compile(r"fastrtps_port\d{1,5}")
#: how old an unheld lock file must be before its files are removed: its owner creates it, then
#: locks it, so one younger may belong to a live process that has not locked it yet
GRACE_SECONDS = 1.0


def port_mutex(port: str) -> str:
    """The name of a port's named semaphore in /dev/shm (``sem_open`` adds ``sem.``)."""
    return f"sem.{port}_mutex"


def lock_held(lock_path: str) -> bool:
    """True while a live process holds the lock file (the owner of its segment or port);
    False once no process does or the file is gone."""
    try:
        fd = os.open(lock_path, os.O_RDONLY)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    finally:
        os.close(fd)
    return False


def files_of(name: str) -> list[str]:
    """Every /dev/shm name that belongs to segment or port ``name``."""
    extra = [port_mutex(name)] if PORT.fullmatch(name) else []
    return [name, *(name + s for s in LOCK_SUFFIXES), *extra]


class ShmSweep:
    """/dev/shm as the run found it (``before``); ``remove_dead`` at its end."""

    def __init__(self, directory: str = SHM_DIR) -> None:
        self.directory = directory
        self.before = self._names()

    def _names(self) -> set[str]:
        try:
            return set(os.listdir(self.directory))
        except OSError:
            return set()

    def new_owners(self) -> set[str]:
        """The segments and ports with a lock file that appeared since ``before``."""
        owners = set()
        for name in self._names() - self.before:
            base = name[:-3] if name.endswith(LOCK_SUFFIXES) else None
            if base is not None and (SEGMENT.fullmatch(base) or PORT.fullmatch(base)):
                owners.add(base)
        return owners

    def _state(self, owner: str, now: float) -> str:
        """"held", "young" (an unheld lock newer than ``GRACE_SECONDS``), or "dead"."""
        state = "dead"
        for suffix in LOCK_SUFFIXES:
            path = os.path.join(self.directory, owner + suffix)
            try:
                made = os.stat(path).st_ctime
            except OSError:
                continue
            if lock_held(path):
                return "held"
            if now - made < GRACE_SECONDS:
                state = "young"
        return state

    def remove_dead(self, wait: float = 2 * GRACE_SECONDS) -> list[str]:
        """Remove the files of every new segment or port whose owner has died (no live process
        holds its lock), waiting up to ``wait`` s for a lock file too young to judge; the
        segments and ports removed, sorted."""
        deadline = time.monotonic() + wait
        removed: list[str] = []
        pending = self.new_owners()
        while pending:
            young = set()
            for owner in sorted(pending):
                state = self._state(owner, time.time())
                if state == "dead":
                    for name in files_of(owner):
                        with contextlib.suppress(FileNotFoundError):
                            os.unlink(os.path.join(self.directory, name))
                    removed.append(owner)
                elif state == "young":
                    young.add(owner)
            pending = young
            if not pending or time.monotonic() > deadline:
                break
            time.sleep(0.1)
        return sorted(removed)
