"""The bounded teardown: a process whose DDS teardown hangs is ended, and the runner can tell.

Fast DDS 2.14 can, rarely, spin forever inside ``rmw_destroy_node`` holding the GIL.  The
stand-in here is a pure-Python busy loop, which also holds the GIL: only a watchdog that
needs no GIL (faulthandler's C thread) can end it.
"""

import subprocess
import sys
import textwrap

from polymatch_ros.ros.ros_env import hung_in_teardown

HUNG = textwrap.dedent("""
    from polymatch_ros.ros.ros_env import teardown_watchdog
    from polymatch_ros.ros.wire import RunRecord
    rec = RunRecord(role="agent", mode="lockstep", t=1.0, agents=(3,), finished=True, steps=20,
    rounds=20)
    print(rec.describe(), flush=True)
    print(rec.to_json(), flush=True)
    with teardown_watchdog(0.5):
        while True:
            pass
""")

CLEAN = textwrap.dedent("""
    import time
    from polymatch_ros.ros.ros_env import teardown_watchdog
    print("agent 3: finished", flush=True)
    with teardown_watchdog(0.3):
        pass
    time.sleep(0.8)          # past the watchdog's deadline: it must have been disarmed
    print("still alive", flush=True)
""")


def _run(code):
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=30)
    return proc.returncode, (proc.stdout + proc.stderr).splitlines()


def test_hung_teardown_is_ended_by_the_watchdog():
    code, lines = _run(HUNG)
    assert code == 1
    assert any(line.startswith("Timeout (") for line in lines)
    assert hung_in_teardown(code, lines)


def test_watchdog_is_disarmed_after_a_clean_teardown():
    code, lines = _run(CLEAN)
    assert code == 0 and lines[-1] == "still alive"
    assert not hung_in_teardown(code, lines)


def test_failure_before_the_final_line_is_not_a_teardown_hang():
    lines = ["agent: error: round timed out waiting for agent 2", "Timeout (0:00:10)!"]
    assert not hung_in_teardown(1, lines)
    assert not hung_in_teardown(2, ["agent 0: finished", "Timeout (0:00:10)!"])
    assert not hung_in_teardown(1, ["agent 0: finished"])
    unfinished = '{"polymatch_run_record": 1, "role": "agent", "mode": "lockstep", "t": 0.5}'
    assert not hung_in_teardown(1, [unfinished, "Timeout (0:00:10)!"])
