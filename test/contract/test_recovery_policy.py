"""The restart policy on its own (``supervisor.recovery``), with stand-ins for processes:
what is restarted, when, how often, and what ends the run."""

import json
import time

import pytest

from polymatch_ros.ros.supervisor.recovery import (
    FAILURE_KEY,
    Failure,
    Recovery,
    RestartPolicy,
)


class DeadProcess:
    """A supervised child whose process ended with ``code`` after printing ``lines``."""

    def __init__(self, name, code=-9, lines=()):
        self.name, self.code, self.lines = name, code, list(lines)
        self.pid, self.starts = 1000, 0
        self.hung_for, self.restart_delay = None, 0.0

    def poll(self):
        return self.code

    def tail(self, n=5):
        return self.lines[-n:]

    def restart(self):
        self.starts += 1
        self.pid += 1
        self.code = None  # running again


def test_a_killed_process_is_restarted_after_its_backoff():
    recovery = Recovery(RestartPolicy(backoff=0.2))
    child = DeadProcess("agent_3", -9, ["agent_3 stepping"])
    assert recovery.died(child, 4.5) is None
    assert recovery.pending(child)
    assert recovery.restart_due([child]) == [] and child.starts == 0  # not before the back-off
    time.sleep(0.25)
    assert recovery.restart_due([child]) == [child] and child.starts == 1
    assert not recovery.pending(child)
    recovery.heard_again("agent_3", resumed_at=42)
    failure = recovery.failures[0]
    assert (failure.process, failure.pid, failure.new_pid, failure.t) == ("agent_3", 1000, 1001,
                                                                          4.5)
    text = failure.describe()
    assert text.startswith("agent_3 (pid 1000) killed by SIGKILL at t = 4.5; restarted after ")
    assert "as pid 1001, back after " in text and text.endswith(", resumed at step 42")


def test_the_backoff_doubles_and_the_third_death_within_the_window_ends_the_run():
    recovery = Recovery(RestartPolicy(most=3, window=30.0, backoff=0.01))
    child = DeadProcess("monitor", 1, ["Traceback (most recent call last):", "MemoryError"])
    due = []
    for _ in range(2):
        assert recovery.died(child, None) is None
        due.append(recovery.due["monitor"] - recovery.failures[-1].died)
        time.sleep(0.05)
        recovery.restart_due([child])
        child.code = 1
    assert due == pytest.approx([0.01, 0.02], abs=1e-9)  # doubled
    error = recovery.died(child, 2.0)
    assert error == ("monitor died 3 times within 30 s (last: exit code 1), not restarted "
                     "again: Traceback (most recent call last): | MemoryError")
    assert not recovery.pending(child) and len(recovery.failures) == 3


def test_deaths_outside_the_window_do_not_count():
    recovery = Recovery(RestartPolicy(most=2, window=0.05, backoff=0.0))
    child = DeadProcess("agent_1")
    assert recovery.died(child, None) is None
    recovery.restart_due([child])
    time.sleep(0.1)
    child.code = -9
    assert recovery.died(child, None) is None  # the first death is out of the window


def test_a_process_that_refused_to_run_is_not_restarted():
    """An error of its own (``agent: error: ...``) would come again: the run ends."""
    recovery = Recovery(RestartPolicy())
    child = DeadProcess("agent_2", 1, ["agent: error: discovery timed out after 30 s waiting "
                                       "for agent(s) 5"])
    error = recovery.died(child, 0.0)
    assert error == ("agent_2 (pid 1000) exited with code 1: agent: error: discovery timed "
                     "out after 30 s waiting for agent(s) 5")
    assert not recovery.pending(child)


def test_on_failure_stop_ends_the_run_at_the_first_death():
    recovery = Recovery(RestartPolicy(restart=False))
    error = recovery.died(DeadProcess("agent_0", -15, ["x"]), 1.0)
    assert error == "agent_0 (pid 1000) exited with code -15: x"
    assert recovery.failures[0].describe() == (
        "agent_0 (pid 1000) killed by SIGTERM at t = 1; not restarted")


def test_a_process_that_died_after_its_run_is_listed_not_restarted():
    """``Supervision.failure`` hands over a process whose final states are in: a death on
    record, no restart due, and the run not ended by it."""
    recovery = Recovery(RestartPolicy())
    child = DeadProcess("agents_2_3", -9, ["{\"finished\": true}"])
    recovery.ended(child, 3.0)
    assert not recovery.pending(child) and recovery.restart_due([child]) == []
    assert child.starts == 0
    (failure,) = recovery.failures
    assert failure.after_run and failure.restarted is None
    assert failure.describe() == ("agents_2_3 (pid 1000) killed by SIGKILL at t = 3 after its "
                                  "run had ended, its final states in; not restarted")
    assert json.loads(failure.to_json())["after_run"] is True


def test_a_failure_is_one_records_line_that_run_record_readers_skip():
    from polymatch_ros.ros.wire import run_records

    failure = Failure("agent_3", 77, -9, 2.5, "last words", died=100.0, restarted=100.5,
                      back=103.0, new_pid=78, resumed_at=12)
    line = failure.to_json()
    data = json.loads(line)
    assert data == {FAILURE_KEY: 1, "process": "agent_3", "pid": 77, "code": -9, "t": 2.5,
                    "last_line": "last words", "new_pid": 78, "resumed_at": 12,
                    "hung_for": None, "after_run": False, "restarted_after": 0.5,
                    "back_after": 3.0}
    assert run_records([line]) == []


def test_a_process_with_a_restart_delay_waits_for_it():
    """The discovery server comes back only once its clients' lease ran out
    (``DiscoveryServer.restart_delay``), whatever the policy's back-off."""
    from polymatch_ros.ros.network.discovery import DiscoveryServer, lease_seconds

    recovery = Recovery(RestartPolicy(backoff=0.5))
    server = DeadProcess("discovery_server")
    server.restart_delay = DiscoveryServer.restart_delay.fget(None)
    assert server.restart_delay == lease_seconds() + 1.0 == 11.0  # the shipped 10 s lease
    assert recovery.died(server, 3.0) is None
    assert recovery.due["discovery_server"] - recovery.failures[-1].died == 11.0
