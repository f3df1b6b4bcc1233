"""A realtime agent between two ticks (``RealtimeAgent._wait_tick``): it sleeps until the tick is
due and serves its node (control, services, parameters) every ``SERVE_PERIOD`` s, not at every
tick, so a spin's wait-set rebuild is paid a few times a second whatever the rate.

The oracle is the wall clock: over a wait of W s the node is served at most W / SERVE_PERIOD
times (and once at the start), never twice within SERVE_PERIOD, the wait ends no sooner than
the tick is due, and a stop ends it at the next serve.  The agent is a stand-in (no ROS
process): only the wait is exercised.
"""

import time
from types import SimpleNamespace

from ros_harness import needs_ros

pytestmark = needs_ros


def _agent(stop_after=None):
    spins = []

    def spin_once(timeout):
        spins.append((time.monotonic(), timeout))
        if stop_after is not None and len(spins) >= stop_after:
            agent.stop_requested = True

    agent = SimpleNamespace(served=0.0, stop_requested=False, late_ticks=0, spin_once=spin_once)
    return agent, spins


def test_the_node_is_served_every_serve_period_and_the_tick_is_not_early():
    from polymatch_ros.ros.agents.realtime import SERVE_PERIOD, RealtimeAgent

    agent, spins = _agent()
    wait = 1.0
    began = time.monotonic()
    due = began + wait
    RealtimeAgent._wait_tick(agent, due, 0.05)
    ended = time.monotonic()
    assert ended >= due
    # at most one serve a period (a busy machine may oversleep: fewer, never more)
    assert 3 <= len(spins) <= wait / SERVE_PERIOD + 2, [round(t - began, 3) for t, _ in spins]
    assert all(timeout == 0.0 for _, timeout in spins)  # never a blocking spin
    gaps = [b - a for (a, _), (b, _) in zip(spins, spins[1:])]
    assert min(gaps) >= SERVE_PERIOD * 0.99, gaps
    assert agent.late_ticks == 0


def test_a_stop_ends_the_wait_at_the_next_serve():
    from polymatch_ros.ros.agents.realtime import SERVE_PERIOD, RealtimeAgent

    agent, spins = _agent(stop_after=2)
    began = time.monotonic()
    RealtimeAgent._wait_tick(agent, began + 5.0, 5.0)
    took = time.monotonic() - began
    assert SERVE_PERIOD * 0.99 <= took < 2.5, took  # at the second serve, long before the tick
    assert len(spins) == 2


def test_a_tick_started_more_than_a_period_late_is_counted():
    from polymatch_ros.ros.agents.realtime import RealtimeAgent

    agent, spins = _agent()
    RealtimeAgent._wait_tick(agent, time.monotonic() - 0.5, 0.1)
    assert agent.late_ticks == 1 and not spins
