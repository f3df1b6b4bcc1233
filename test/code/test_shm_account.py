"""The suite's /dev/shm account (test/support/shm_account.py) names what a run left there and the
test during which it appeared, across xdist's workers, and leaves out what a live process still
holds or what was there before.  The oracle: a small suite, written here, whose tests make
Fast DDS-like entries (a segment and its lock file) of names only this test uses, one of them
held (``flock``) by a process that outlives the run, one there before it; pytest's output is
read as a user reads it.
"""

import os
import signal
import subprocess
import sys
import uuid

import pytest

SUPPORT = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "support")

CONFTEST = '''
import shm_account


def pytest_configure(config):
    shm_account.register(config)
'''

TESTS = '''
import fcntl
import os
import subprocess

TAG = os.environ["SHM_TAG"]


def make(name):
    for path in (f"/dev/shm/{name}", f"/dev/shm/{name}_el"):
        open(path, "w").close()


def test_clean():
    pass


def test_leaves_one():
    make(f"fastrtps_{TAG}a")


def test_leaves_one_a_live_process_holds():
    make(f"fastrtps_{TAG}b")
    fd = os.open(f"/dev/shm/fastrtps_{TAG}b_el", os.O_RDWR)
    fcntl.flock(fd, fcntl.LOCK_EX)  # held by the sleeper, which shares the open file
    sleeper = subprocess.Popen(["sleep", "120"], pass_fds=(fd,))
    os.close(fd)
    with open(os.environ["SHM_HOLDER"], "w") as fh:
        fh.write(str(sleeper.pid))


def test_removes_its_own():
    make(f"fastrtps_{TAG}c")
    for path in (f"/dev/shm/fastrtps_{TAG}c", f"/dev/shm/fastrtps_{TAG}c_el"):
        os.unlink(path)
'''


def _account(stdout, tag):
    """The account's line, as {entry: [tests]} for the entries of this test's ``tag``."""
    lines = [line for line in stdout.splitlines() if line.startswith("/dev/shm:")]
    assert len(lines) == 1, stdout
    named = {}
    for part in lines[0].split("; ")[1:]:
        name, _, tests = part.partition(" (appeared during: ")
        named[name] = tests.rstrip(")").split(", ")
    return {name: tests for name, tests in named.items() if tag in name}


@pytest.mark.parametrize("workers", ["0", "2"])
def test_the_account_names_what_a_run_left_and_the_test_it_appeared_in(tmp_path, workers):
    tag = uuid.uuid4().hex[:12]
    (tmp_path / "conftest.py").write_text(CONFTEST)
    (tmp_path / "test_shm.py").write_text(TESTS)
    holder = tmp_path / "holder.pid"
    before = [f"/dev/shm/fastrtps_{tag}z{s}" for s in ("", "_el")]  # there before the run
    for path in before:
        open(path, "w").close()
    env = {**os.environ, "PYTHONPATH": SUPPORT, "SHM_TAG": tag, "SHM_HOLDER": str(holder)}
    try:
        proc = subprocess.run(
            [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-n", workers,
             "-c", os.devnull, "--rootdir", str(tmp_path), str(tmp_path)],
            cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120, check=False)
    finally:
        if holder.exists():
            os.kill(int(holder.read_text()), signal.SIGKILL)
        for name in [f"fastrtps_{tag}{k}{s}" for k in "abcz" for s in ("", "_el")]:
            if os.path.exists(f"/dev/shm/{name}"):
                os.unlink(f"/dev/shm/{name}")
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert "4 passed" in proc.stdout, proc.stdout
    account = _account(proc.stdout, tag)
    assert sorted(account) == [f"fastrtps_{tag}a", f"fastrtps_{tag}a_el"], account
    for tests in account.values():
        # alone, the test that made it; beside it on another worker, maybe another one too
        assert "test_shm.py::test_leaves_one" in tests and (workers != "0" or len(tests) == 1)
