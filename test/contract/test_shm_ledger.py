"""The runner's ledger of its children's Fast DDS segments (``supervisor.shm``): it removes a
segment its child made once the child has died, never one whose owner lives, never one it did
not note.

Each "child" here is a plain process that does what a Fast DDS participant does in /dev/shm
(a segment file, and a lock file it holds with ``flock`` while it lives); the oracle is the
files themselves, and the processes' states.
"""

import contextlib
import os
import secrets
import signal
import subprocess
import sys

from polymatch_ros.ros.supervisor.shm import SegmentLedger

OWNER = """
import fcntl, os, sys
name = sys.argv[1]
open(name, "wb").close()
lock = os.open(name + "_el", os.O_CREAT | os.O_RDWR, 0o644)
fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
print("holding", flush=True)
sys.stdin.read()
"""


def _owner(path):
    """A process that made ``path`` and holds ``path``_el locked until it dies."""
    proc = subprocess.Popen([sys.executable, "-c", OWNER, path], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "holding"
    return proc


def _exists(path):
    return os.path.exists(path) and os.path.exists(path + "_el")


def test_removes_what_a_dead_child_left_and_nothing_of_a_live_or_unnoted_process():
    tag = f"fastrtps_{secrets.token_hex(8)}"
    child, live, stranger = (f"/dev/shm/{tag}_{who}" for who in ("child", "live", "stranger"))
    procs = [_owner(child), _owner(live), _owner(stranger)]
    try:
        ledger = SegmentLedger()
        ledger.note([procs[0].pid, procs[1].pid], force=True)
        assert ledger.segments == {os.path.basename(child), os.path.basename(live)}
        assert ledger.remove_ended() == [] and _exists(child)      # its owner still runs
        procs[0].send_signal(signal.SIGKILL)
        procs[0].wait(timeout=10)
        procs[2].send_signal(signal.SIGKILL)  # dead too, but never noted
        procs[2].wait(timeout=10)
        assert ledger.remove_ended() == [os.path.basename(child)]
        assert not os.path.exists(child) and not os.path.exists(child + "_el")
        assert _exists(live) and _exists(stranger)
    finally:
        for proc in procs:
            with contextlib.suppress(ProcessLookupError):
                proc.kill()
            proc.wait(timeout=10)
        for path in (child, live, stranger):
            for name in (path, path + "_el"):
                with contextlib.suppress(FileNotFoundError):
                    os.unlink(name)
