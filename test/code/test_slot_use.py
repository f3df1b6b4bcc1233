"""`test/support/slot_use.py`: each hold of a ROS slot is logged with its wall and CPU
seconds, and the report sums them and names the tests that mostly wait."""

import json
import subprocess
import sys

import pytest
import ros_harness
import slot_use

SUPPORT = slot_use.__file__


def test_a_hold_of_a_ros_slot_is_logged_with_its_wall_and_cpu_seconds(tmp_path, monkeypatch):
    log = tmp_path / "slots.jsonl"
    monkeypatch.setenv("POLYMATCH_SLOT_LOG", str(log))
    monkeypatch.setattr(ros_harness, "SLOT_DIR", str(tmp_path / "slots"))
    with ros_harness.ros_slot():
        subprocess.run([sys.executable, "-c", "sum(range(3_000_000))"], check=True, timeout=60)
    (line,) = [json.loads(text) for text in log.read_text().splitlines()]
    assert line["test"].startswith("test/code/test_slot_use.py::")
    assert line["wall"] >= line["cpu"] > 0


def test_nothing_is_logged_without_the_variable(tmp_path, monkeypatch):
    monkeypatch.delenv("POLYMATCH_SLOT_LOG", raising=False)
    monkeypatch.chdir(tmp_path)
    with slot_use.held():
        pass
    assert list(tmp_path.iterdir()) == []


def test_the_report_sums_the_holds_and_flags_the_tests_that_mostly_wait():
    lines = [{"test": "busy", "wall": 10.0, "cpu": 9.0},
             {"test": "idle", "wall": 20.0, "cpu": 2.0},
             {"test": "sleepy", "wall": 5.0, "cpu": 0.5}]
    text = slot_use.report(lines)
    assert "| 3 | 35 | 12 | 0.33 |" in text
    assert "| 20.0 | 0.10 | yes | idle |" in text
    assert "| 10.0 | 0.90 |  | busy |" in text
    assert text.index("| 20.0 ") < text.index("| 10.0 ") < text.index("| 5.0 ")


@pytest.mark.parametrize("args", [[], ["a", "b"], ["/nonexistent/slots.jsonl"]])
def test_the_report_refuses_bad_input_in_one_line(args):
    res = subprocess.run([sys.executable, SUPPORT, *args], capture_output=True, text=True,
                         timeout=60)
    assert res.returncode == 2 and res.stdout == ""
    assert len(res.stderr.strip().splitlines()) == 1 and "Traceback" not in res.stderr
