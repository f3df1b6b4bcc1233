"""The lockstep states the monitor reads go out at its pace, at steps every process sends
(``agents.state_stride``): so every step it reports is one that all agents reached, exact as
the centralised run has it (lockstep = centralised, Theorems 4.1/4.2 then the simulator's).

The oracle is brute force: processes stepping at their own paces on fake clocks, the steps
each one sends written down, their intersection (the steps the monitor can complete) and the
wall-clock gaps between those counted directly.
"""

import itertools

import pytest

from polymatch_ros.ros.agents.state_stride import MOST_STEPS, StateStride, power_of_two_within


class FakeClock:
    def __init__(self):
        self.now = 0.0

    def __call__(self):
        return self.now


def _sent(rate, per_step, steps, jitter=()):
    """The steps one process sends in a run of ``steps`` steps of ``per_step`` s each (times
    ``jitter[k % len]`` if given)."""
    clock = FakeClock()
    stride = StateStride(rate, clock)
    out = []
    assert stride.due(0)  # the initial state
    out.append(0)
    for k in range(1, steps + 1):
        clock.now += per_step * (jitter[k % len(jitter)] if jitter else 1.0)
        if stride.due(k, last=k == steps):
            out.append(k)
    return out, clock


def test_rate_zero_sends_every_step():
    sent, _ = _sent(0.0, 1e-4, 50)
    assert sent == list(range(51))


@pytest.mark.parametrize("paces", [(1e-4, 1e-4, 1e-4), (1e-4, 1.6e-4, 0.7e-4),
                                   (2e-3, 2.5e-3, 3e-3), (5e-5, 9e-5, 6e-5, 1e-4)])
def test_every_process_sends_common_steps_at_the_monitors_pace(paces):
    """Processes in lockstep step within a factor two of each other's pace: the steps all of
    them send (brute-force intersection) come at least every two exchange periods of wall
    time after the strides settle, far fewer than every step, and include the last."""
    rate, steps = 40.0, 20000
    runs = [_sent(rate, pace, steps) for pace in paces]
    common = sorted(set.intersection(*(set(sent) for sent, _ in runs)))
    assert common[0] == 0 and common[-1] == steps
    slowest = max(paces)
    gaps = [(b - a) * slowest for a, b in zip(common, common[1:])]
    settled = gaps[len(gaps) // 4:]
    assert max(settled) <= 2.0 / rate + 1e-12, max(settled)
    for sent, _ in runs:  # each process sends at most about twice per exchange period of
        # the slowest pace, not a message a step
        assert len(sent) <= 2 * rate * steps * max(paces) + 10


def test_the_strides_are_powers_of_two_so_the_largest_divides_them_all():
    for period, per_step in itertools.product((0.025, 0.05, 1.0), (1e-6, 3e-5, 1e-3, 0.02)):
        s = power_of_two_within(period, per_step)
        assert s & (s - 1) == 0 and 1 <= s <= MOST_STEPS
        assert s == 1 or s * per_step <= period          # within the period ...
        assert 2 * s * per_step > period or s == MOST_STEPS  # ... and the largest such


def test_a_slower_pace_shortens_the_stride():
    """A process that slows down 20-fold (a loaded machine) sends more often in steps, not
    less often in time: a gap of a few periods where the pace falls, then within two."""
    period, pace = 1 / 40.0, 1e-4
    jitter = [1.0] * 500 + [20.0] * 500
    sent, _ = _sent(40.0, pace, 4000, jitter)
    gaps = [b - a for a, b in zip(sent, sent[1:])]
    assert min(gaps) < max(gaps)  # the stride changed with the pace
    clock, sends = FakeClock(), []
    stride = StateStride(40.0, clock)
    stride.due(0)
    for k in range(1, 4001):
        slow = jitter[k % len(jitter)] > 1.0
        clock.now += pace * jitter[k % len(jitter)]
        if stride.due(k):
            sends.append((clock.now, slow))
    gaps = [(b - a, slow) for (a, _), (b, slow) in zip(sends, sends[1:])]
    assert max(g for g, _ in gaps[4:]) <= 4 * period
    steady = [g for (g, slow), (_, before) in zip(gaps[1:], gaps) if slow and before]
    assert steady and max(steady[2:]) <= 2 * period
