"""`test/support/repeat_tests.py`, the 20-run loop: a green run names each test that passed
only on its rerun, and what it left in /dev/shm, and keeps that run's pytest output."""

import contextlib
import os
import pathlib
import subprocess
import sys
import uuid

ROOT = pathlib.Path(__file__).resolve().parents[2]
LOOP = ROOT / "test" / "support" / "repeat_tests.py"

FLAKY_ONCE = '''
import pathlib
import pytest

@pytest.mark.flaky(reruns=1)
def test_fails_on_its_first_try():
    mark = pathlib.Path(__file__).with_name("tried")
    first = not mark.exists()
    mark.touch()
    assert not first, "first try"

def test_passes():
    pass
'''


def test_a_green_run_names_the_tests_that_needed_their_rerun(tmp_path):
    (tmp_path / "test_flaky_once.py").write_text(FLAKY_ONCE)
    logs = tmp_path / "logs"
    loop = subprocess.run(
        [sys.executable, str(LOOP), "--runs", "1", "--timeout", "120", "--logs", str(logs),
         str(tmp_path / "test_flaky_once.py"), "-p", "no:xdist", "-raR"],
        capture_output=True, text=True, timeout=180, check=False)
    lines = loop.stdout.splitlines()
    assert loop.returncode == 0 and lines[0].startswith("run 1/1: green"), loop.stdout
    assert "1 rerun" in lines[0], loop.stdout
    assert lines[1].startswith("  rerun: "), loop.stdout
    assert lines[1].endswith("test_flaky_once.py::test_fails_on_its_first_try"), loop.stdout
    assert lines[2:] == ["runs: 1 passed, 0 failed"], loop.stdout
    kept = (logs / "run_1.txt").read_text()
    assert "RERUN" in kept and "2 passed, 1 rerun" in kept, kept


LEAVES_ONE = '''
import os


def test_leaves_a_segment():
    for suffix in ("", "_el"):
        open(f"/dev/shm/fastrtps_{os.environ['SHM_TAG']}{suffix}", "w").close()
'''

ACCOUNT = '''
import shm_account


def pytest_configure(config):
    shm_account.register(config)
'''


def test_a_run_that_left_something_in_dev_shm_says_what_and_keeps_its_output(tmp_path):
    """The oracle: the entries the run's one test made, under a name only this test uses."""
    tag = uuid.uuid4().hex[:12]
    (tmp_path / "conftest.py").write_text(ACCOUNT)
    (tmp_path / "test_leaves_one.py").write_text(LEAVES_ONE)
    logs = tmp_path / "logs"
    env = {**os.environ, "SHM_TAG": tag, "PYTHONPATH": str(LOOP.parent)}
    try:
        loop = subprocess.run(
            [sys.executable, str(LOOP), "--runs", "1", "--timeout", "120", "--logs", str(logs),
             str(tmp_path / "test_leaves_one.py"), "-p", "no:xdist", "--rootdir", str(tmp_path),
             "-c", os.devnull],
            env=env, capture_output=True, text=True, timeout=180, check=False)
    finally:
        for suffix in ("", "_el"):
            with contextlib.suppress(FileNotFoundError):
                os.unlink(f"/dev/shm/fastrtps_{tag}{suffix}")
    lines = loop.stdout.splitlines()
    assert loop.returncode == 0 and lines[0].startswith("run 1/1: green"), loop.stdout
    assert lines[1].startswith("  /dev/shm: ") and lines[-1] == "runs: 1 passed, 0 failed"
    assert f"; fastrtps_{tag} (appeared during: test_leaves_one.py::test_leaves_a_segment)" \
        in lines[1], lines[1]
    assert lines[1].strip() in (logs / "run_1.txt").read_text()
