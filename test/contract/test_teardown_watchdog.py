"""The bounded teardown: a process whose DDS teardown hangs is ended, and the runner can tell.

Fast DDS 2.14 can, rarely, spin forever inside ``rmw_destroy_node`` holding the GIL.  The
stand-in here is a pure-Python busy loop, which also holds the GIL: only a watchdog that
needs no GIL can end it: faulthandler's C thread
dumps the stack, a POSIX timer's libc thread exits with the code the process had decided on.
"""

import subprocess
import sys
import textwrap

from polymatch_ros.ros.process.teardown import hung_in_teardown

HUNG = textwrap.dedent("""
    from polymatch_ros.ros.process.teardown import teardown_watchdog
    from polymatch_ros.ros.wire import RunRecord
    rec = RunRecord(role="agent", mode="lockstep", t=1.0, agents=(3,), finished=True, steps=20,
    rounds=20)
    print(rec.describe(), flush=True)
    print(rec.to_json(), flush=True)
    with teardown_watchdog(0.5, exit_code=EXIT_CODE):
        while True:
            pass
""")

CLEAN = textwrap.dedent("""
    import time
    from polymatch_ros.ros.process.teardown import teardown_watchdog
    print("agent 3: finished", flush=True)
    with teardown_watchdog(0.3, exit_code=5):
        pass
    time.sleep(1.2)          # past the watchdog's deadline: it must have been disarmed
    print("still alive", flush=True)
""")


def _run(code, exit_code=0):
    code = code.replace("EXIT_CODE", str(exit_code))
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=30)
    return proc.returncode, (proc.stdout + proc.stderr).splitlines()


def test_hung_teardown_is_ended_by_the_watchdog_with_the_process_s_own_exit_code():
    for wanted in (0, 3):
        code, lines = _run(HUNG, exit_code=wanted)
        assert code == wanted
        assert any(line.startswith("Timeout (") for line in lines)
        assert hung_in_teardown(code, lines)


def test_without_a_native_timer_faulthandler_ends_the_hung_teardown_with_1():
    no_timer = HUNG.replace(
        "from polymatch_ros.ros.process.teardown import teardown_watchdog",
        "import polymatch_ros.ros.process.exit_timer as t\n"
        "t.native_exit_timer = lambda *a: None\n"
        "from polymatch_ros.ros.process.teardown import teardown_watchdog",
    )
    code, lines = _run(no_timer)
    assert code == 1
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


def _child(code):
    from polymatch_ros.ros.supervisor.children import Child

    return Child("agent_3", [sys.executable, "-c", code], env=None)


def test_runner_ends_a_process_that_overstays_after_its_final_record():
    """Belt and braces: even if a process's own watchdog never fires, the runner ends a child
    that printed its finished record and kept running, and counts it as ended well."""
    import time

    stuck = HUNG.replace("with teardown_watchdog(0.5, exit_code=EXIT_CODE):", "if True:")
    child = _child(stuck)
    try:
        deadline = time.monotonic() + 20
        while child.reported_at is None and time.monotonic() < deadline:
            time.sleep(0.05)
        assert child.reported_at is not None
        assert not child.end_if_overstaying(30.0)  # not yet overdue
        time.sleep(0.6)
        assert child.end_if_overstaying(0.5)
        assert child.poll() is not None and child.ended_well() and child.hung_in_teardown()
    finally:
        child.stop(grace=0.5)


def test_runner_leaves_a_process_without_its_final_record_alone():
    import time

    child = _child("import time\nprint('agent 3: stepping', flush=True)\ntime.sleep(30)")
    try:
        time.sleep(0.8)
        assert not child.end_if_overstaying(0.1)
        assert child.poll() is None and not child.ended_well()
    finally:
        child.stop(grace=0.5)
