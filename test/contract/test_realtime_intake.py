"""How agents and the monitor date their peers' poses: with the middleware's reception time
(``wire.intake.received_at``).

The clock offsets of the realtime agents (the delays of Theorem 4.2's setting, measured) rest on
that stamp.
"""

import time

import pytest

from polymatch_ros.ros.wire.intake import received_at


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
