"""The monitor's lockstep intake of block messages (``nodes.held_steps.HeldSteps``): a step is
complete once the states of every agent have come, whichever blocks (or parts of a block, on
hosts that split one) carried them; only then is it handed over, and the steps before it
are forgotten.  The oracle: the steps and agents each message carries, chosen here, and the
latest step whose messages cover every agent, found by brute force over them.
"""

import random

import pytest
from ros_harness import needs_ros

pytestmark = needs_ros

RUN_ID, N, K, T_MAX = 5, 6, 4, 100.0  # 6 agents in blocks of 4: block 0 = 0..3, block 1 = 4, 5


def _msg(block, agents, step, run_id=RUN_ID, nanosec=None):
    from polymatch_interfaces.msg import AgentStateBlock

    msg = AgentStateBlock(run_id=run_id, block=block, agents=list(agents))
    msg.header.stamp.sec = step
    msg.header.stamp.nanosec = 0 if nanosec is None else nanosec
    msg.centroids = [0.0] * (2 * len(agents))
    msg.rotations = [1.0, 0.0, 0.0, 1.0] * len(agents)
    return msg


def _held():
    from polymatch_ros.core.so import SO2
    from polymatch_ros.ros.nodes.held_steps import HeldSteps

    return HeldSteps(N, K, RUN_ID, T_MAX, SO2(), 2)


def _key(step):
    return step * 1_000_000_000


def test_the_newest_step_every_agent_reached_is_the_complete_one():
    held = _held()
    for step in (1, 2, 3):
        assert held.hold(0, _msg(0, range(4), step), 0.0, -1) is None
    for step in (1, 2):
        assert held.hold(1, _msg(1, [4, 5], step), 0.0, -1) is None
    assert held.newest_complete() == _key(2)  # block 1 has not sent step 3 yet
    got = held.take(_key(2))
    assert sorted((b, list(m.agents)) for b, m, _ in got) == [(0, [0, 1, 2, 3]), (1, [4, 5])]
    assert held.newest_complete() is None and list(held.steps) == [_key(3)]


def test_a_block_split_across_hosts_completes_with_both_parts():
    held = _held()
    assert held.hold(0, _msg(0, [0, 1], 7), 0.0, -1) is None
    assert held.hold(1, _msg(1, [4, 5], 7), 0.0, -1) is None
    assert held.newest_complete() is None
    assert held.hold(0, _msg(0, [2, 3], 7), 0.0, -1) is None
    assert held.newest_complete() == _key(7)


def test_repeats_and_stale_steps_are_told_apart():
    held = _held()
    assert held.hold(0, _msg(0, range(4), 4), 0.0, -1) is None
    assert held.hold(0, _msg(0, range(4), 4), 0.0, -1) == "repeat"  # the same message again
    assert held.hold(1, _msg(1, [4, 5], 3), 0.0, _key(3)) == "repeat"  # the completed step
    assert held.hold(1, _msg(1, [4, 5], 2), 0.0, _key(3)) == "stale"


@pytest.mark.parametrize("what,msg,reason", [
    ("another run", lambda: _msg(0, range(4), 1, run_id=RUN_ID + 1), "unknown sender (run id)"),
    ("another block's topic", lambda: _msg(1, range(4), 1), "unknown sender (agent index)"),
    ("nanoseconds of a whole second", lambda: _msg(0, range(4), 1, nanosec=10**9),
     "malformed header"),
    ("past t_end", lambda: _msg(0, range(4), 200), "stamp outside the run"),
    ("no agents", lambda: _msg(0, [], 1), "malformed layout"),
])
def test_a_refused_message_is_not_held_and_names_its_reason(what, msg, reason):
    held = _held()
    assert held.hold(0, msg(), 0.0, -1) == reason
    assert not held.steps


def test_random_arrivals_complete_the_step_brute_force_finds():
    rng = random.Random(11)
    for _ in range(50):
        held, sent = _held(), []
        for step in range(1, 9):
            for block, agents in ((0, range(4)), (1, [4, 5])):
                if rng.random() < 0.7:
                    sent.append((block, agents, step))
        rng.shuffle(sent)
        for block, agents, step in sent:
            held.hold(block, _msg(block, agents, step), 0.0, -1)
        covered = {}
        for _, agents, step in sent:
            covered.setdefault(step, set()).update(agents)
        full = [s for s, agents in covered.items() if len(agents) == N]
        assert held.newest_complete() == (_key(max(full)) if full else None)
