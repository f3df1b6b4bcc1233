"""How agents and the monitor take their peers' poses: at the tick, from readers on a lean node
(``exchange.drain``), stamped with the middleware's reception time (``exchange.received_at``).

The clock offsets of the realtime agents (the delays of Theorem 4.2's setting, measured) rest on
that stamp, and every pose the readers hold must be taken once the tick comes.
"""

import time
from collections import deque

import pytest

from polymatch_ros.ros.nodes.process_io import drain, received_at


def _clocks():
    return time.time(), time.monotonic()


def test_received_at_is_the_middleware_reception_time_on_both_clocks():
    """Bracketed by the clocks read before and after the call (a loaded machine may take any
    time between two reads)."""
    before_wall, before_mono = _clocks()
    stamp_ns = int((before_wall - 0.25) * 1e9)
    wall, mono = received_at({"received_timestamp": stamp_ns})
    after_wall, after_mono = _clocks()
    assert wall == pytest.approx(stamp_ns * 1e-9, abs=1e-6)
    earliest, latest = before_mono - (after_wall - wall), after_mono - (before_wall - wall)
    assert earliest - 1e-6 <= mono <= latest + 1e-6


@pytest.mark.parametrize("info", [None, {}, {"received_timestamp": 0}])
def test_received_at_is_now_without_a_reception_time(info):
    before_wall, before_mono = _clocks()
    wall, mono = received_at(info)
    after_wall, after_mono = _clocks()
    assert before_wall <= wall <= after_wall and before_mono <= mono <= after_mono


def test_received_at_never_lies_in_the_future():
    wall, mono = received_at({"received_timestamp": int((time.time() + 5.0) * 1e9)})
    assert wall <= time.time() and mono <= time.monotonic()


class WaitSetExecutor:
    """rclpy's ``spin_once(0)``: a wait finds the readers that hold a message and runs one
    callback per call, taking one message of one reader; once they are done, one call comes back
    empty (the wait's timeout has passed), and the next waits anew."""

    def __init__(self, queues):
        self.queues = queues  # reader -> deque of messages
        self.batch, self.exhausted, self.taken, self.calls = [], False, [], 0

    def spin_once(self, timeout_sec):
        assert timeout_sec == 0.0
        self.calls += 1
        if not self.batch and self.exhausted:
            self.exhausted = False
            return
        if not self.batch:
            self.batch = [r for r, q in self.queues.items() if q]
            if not self.batch:
                return
        reader = self.batch.pop(0)
        self.taken.append(self.queues[reader].popleft())
        self.exhausted = not self.batch


def test_drain_takes_every_message_of_every_reader_across_waits():
    queues = {r: deque(f"{r}{i}" for i in range(n)) for r, n in zip("abc", (5, 1, 3))}
    ex = WaitSetExecutor(queues)
    drain(ex, lambda: len(ex.taken), most=100)
    assert sorted(ex.taken) == sorted(["a0", "a1", "a2", "a3", "a4", "b0", "c0", "c1", "c2"])
    assert not any(queues.values())
    assert ex.calls == 9 + 5 + 1  # an empty call after each of 5 waits, a last wait finds none


def test_drain_of_empty_readers_costs_two_calls():
    ex = WaitSetExecutor({"a": deque(), "b": deque()})
    drain(ex, lambda: len(ex.taken), most=100)
    assert ex.taken == [] and ex.calls == 2


def test_drain_stops_at_most_callbacks():
    ex = WaitSetExecutor({"a": deque(range(50))})
    drain(ex, lambda: len(ex.taken), most=7)
    assert len(ex.taken) == 7 and len(ex.queues["a"]) == 43
