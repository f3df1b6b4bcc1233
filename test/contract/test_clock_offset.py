"""Realtime peers' clock offsets estimated from pose stamps (``ros/agents/clock_offset.py``)."""

import numpy as np
import pytest

from polymatch_ros.ros.agents.clock_offset import ClockOffsets
from polymatch_ros.ros.wire import RunRecord

EPOCH, SCALE, RATE = 1000.0, 3.0, 20.0


def feed(clocks, agent, offset, latencies, first_tick=1):
    """Poses of ``agent`` (clock ``offset`` s ahead of ours) on the shared schedule: tick k has
    t = k * SCALE / RATE, sent at EPOCH + k / RATE on its clock, received ``latency`` later."""
    for k, latency in enumerate(latencies, start=first_tick):
        sent_on_our_clock = EPOCH + k / RATE - offset
        clocks.add(agent, k * SCALE / RATE, sent_on_our_clock + latency)


@pytest.mark.parametrize("offset", [0.3, -0.25, 0.0])
def test_the_least_delayed_pose_gives_the_offset(offset):
    clocks = ClockOffsets(SCALE, threshold=0.1)
    clocks.start(EPOCH)
    rng = np.random.default_rng(3)
    feed(clocks, 4, offset, rng.uniform(0.002, 0.08, size=40))
    assert clocks.offsets()[4] == pytest.approx(offset, abs=0.01)
    assert clocks.offsets()[4] <= offset              # latency only ever hides clock ahead


def test_nothing_before_the_start_and_no_initial_pose():
    clocks = ClockOffsets(SCALE, threshold=0.1)
    feed(clocks, 1, 5.0, [0.01] * 5)                  # no epoch yet
    clocks.start(EPOCH)
    clocks.add(1, 0.0, EPOCH + 7.0)                   # the initial pose, announced before t = 0
    assert clocks.offsets() == {}


def test_warns_once_per_crossing_and_forgets_old_poses():
    clocks = ClockOffsets(SCALE, threshold=0.1, window=10)
    clocks.start(EPOCH)
    feed(clocks, 2, 0.02, [0.005] * 10)
    feed(clocks, 3, 0.5, [0.005] * 10)
    assert clocks.over_threshold() == [(3, pytest.approx(0.495))]
    assert clocks.over_threshold() == []              # said once
    feed(clocks, 3, 0.0, [0.005] * 10, first_tick=11)  # its clock was corrected
    assert clocks.offsets()[3] == pytest.approx(-0.005) and clocks.over_threshold() == []
    feed(clocks, 3, -0.4, [0.005] * 10, first_tick=21)
    assert clocks.over_threshold() == [(3, pytest.approx(-0.405))]


def test_the_run_record_carries_the_offsets():
    rec = RunRecord(role="agent", mode="realtime", t=3.0, agents=(0,), peers=(1, 2),
                    clock_offsets={1: -0.004, 2: 0.25})
    back = RunRecord.from_json(rec.to_json())
    assert back.clock_offsets == {1: -0.004, 2: 0.25}
    assert RunRecord.from_json(rec.to_json().replace('"1": -0.004', '"x": 1')) is None
