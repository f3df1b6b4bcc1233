"""`test/support/repeat_tests.py`, the 20-run loop: a green run names each test that passed
only on its rerun, and keeps that run's pytest output."""

import pathlib
import subprocess
import sys

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
