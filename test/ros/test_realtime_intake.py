"""How agents and the monitor take their peers' poses: at the tick, from readers on a lean node
(``exchange.drain``), stamped with the middleware's reception time (``exchange.received_at``).

The clock offsets of the realtime agents (the delays of Theorem 4.2's setting, measured) rest on
that stamp, and every pose the readers hold must be taken once the tick comes.
"""

import time
from collections import deque

import pytest

from polymatch_ros.ros.nodes.exchange import drain, received_at


def test_received_at_is_the_middleware_reception_time_on_both_clocks():
    now_wall, now_mono = time.time(), time.monotonic()
    wall, mono = received_at({"received_timestamp": int((now_wall - 0.25) * 1e9)})
    assert wall == pytest.approx(now_wall - 0.25, abs=0.01)
    assert mono == pytest.approx(now_mono - 0.25, abs=0.01)


@pytest.mark.parametrize("info", [None, {}, {"received_timestamp": 0}])
def test_received_at_is_now_without_a_reception_time(info):
    wall, mono = received_at(info)
    assert wall == pytest.approx(time.time(), abs=0.01)
    assert mono == pytest.approx(time.monotonic(), abs=0.01)


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
