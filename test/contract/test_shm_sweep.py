"""The runner's sweep of /dev/shm (``supervisor.shm``): at the run's end it removes the Fast DDS
files of every segment and port that appeared during the run and whose owner has died, and
nothing else: not a file that was there before, not one a live process holds, not one whose
lock is too new to judge, not a name that is not Fast DDS's.

Each owner here is a plain process that does what a Fast DDS participant does (a segment file,
a lock file it holds with ``flock`` while it lives; a port's semaphore), in a folder of the
test's own; the oracle is the files themselves and the processes' states.
"""

import contextlib
import os
import secrets
import signal
import subprocess
import sys
import time

from polymatch_ros.ros.supervisor.shm import GRACE_SECONDS, ShmSweep

OWNER = """
import fcntl, os, sys, time
folder, name, lock, delay = sys.argv[1], sys.argv[2], sys.argv[3], float(sys.argv[4])
open(os.path.join(folder, name), "wb").close()
fd = os.open(os.path.join(folder, name + lock), os.O_CREAT | os.O_RDWR, 0o644)
time.sleep(delay)  # a new lock file, not locked yet
fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
print("holding", flush=True)
sys.stdin.read()
"""


def _owner(folder, name, lock="_el", delay=0.0, wait=True):
    """A process that made ``name`` and holds ``name + lock`` locked until it dies."""
    proc = subprocess.Popen([sys.executable, "-c", OWNER, str(folder), name, lock, str(delay)],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    if wait:
        assert proc.stdout.readline().strip() == "holding"
    return proc


def _kill(proc):
    with contextlib.suppress(ProcessLookupError):
        proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=10)


def _segment():
    return f"fastrtps_{secrets.token_hex(8)}"


def test_removes_what_dead_owners_left_during_the_run_and_nothing_else(tmp_path):
    before, dead, live, port = _segment(), _segment(), _segment(), "fastrtps_port7411"
    odd = f"fastrtps_{secrets.token_hex(4)}_child"  # not a name Fast DDS gives
    earlier = _owner(tmp_path, before)
    _kill(earlier)                                   # dead, but there before the run
    sweep = ShmSweep(str(tmp_path))
    owners = [_owner(tmp_path, dead), _owner(tmp_path, live), _owner(tmp_path, port, "_sl"),
              _owner(tmp_path, odd)]
    (tmp_path / f"sem.{port}_mutex").touch()
    try:
        for proc in (owners[0], owners[2], owners[3]):
            _kill(proc)
        time.sleep(GRACE_SECONDS)  # every lock file old enough to judge
        assert sweep.remove_dead() == sorted([dead, port])
        assert sorted(os.listdir(tmp_path)) == sorted(
            [before, before + "_el", live, live + "_el", odd, odd + "_el"])
    finally:
        for proc in owners:
            _kill(proc)


def test_a_lock_file_too_new_to_judge_is_waited_for(tmp_path):
    """An owner that has made its lock file and locks it a moment later is alive: the sweep
    waits for the lock file to be ``GRACE_SECONDS`` old before it judges."""
    sweep = ShmSweep(str(tmp_path))
    late = _segment()
    proc = _owner(tmp_path, late, delay=0.5 * GRACE_SECONDS, wait=False)
    try:
        while not (tmp_path / (late + "_el")).exists():
            time.sleep(0.01)
        assert sweep.remove_dead() == []
        assert proc.stdout.readline().strip() == "holding"
        assert sorted(os.listdir(tmp_path)) == [late, late + "_el"]
        _kill(proc)
        assert sweep.remove_dead() == [late] and os.listdir(tmp_path) == []
    finally:
        _kill(proc)
