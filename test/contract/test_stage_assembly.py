"""A lockstep round's ensemble is the same whichever way the peers' rows came: assembled array
by array from whole messages (``wire.assemble_rows``, what the agents use) or row by row
(``wire.assemble``), bit for bit, so the distributed run stays the centralised one to
round-off (Theorems 4.1/4.2 are then the simulator's).  No DDS."""

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from ros_harness import needs_ros

pytestmark = needs_ros

SETTINGS = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
N = 12                 # agents of the scene: a group [START, START + SIZE) among them
START, SIZE = 3, 6


def _group(kind):
    from polymatch_ros.core.so import SO2, SO3, SOn

    return {"angle": SO2(), "so3": SO3(), "so4": SOn(4)}[kind]


def _rotations(grp, n, rng):
    q = np.linalg.qr(rng.normal(size=(n, grp.dim, grp.dim)))[0]
    q[np.linalg.det(q) < 0, :, 0] *= -1
    return grp.from_matrices(q)


@SETTINGS
@given(
    kind=st.sampled_from(["angle", "so3", "so4"]),
    senders=st.lists(st.lists(st.integers(0, N - 1), min_size=1, max_size=5, unique=True),
                     min_size=0, max_size=4),
    local=st.lists(st.integers(0, SIZE - 1), max_size=3, unique=True),
    with_x=st.booleans(),
    with_v=st.booleans(),
    seed=st.integers(0, 2**16),
)
def test_rows_assembled_by_message_equal_rows_assembled_one_by_one(kind, senders, local, with_x,
                                                                   with_v, seed):
    from polymatch_ros.core.model import GroupState
    from polymatch_ros.ros import wire

    grp, rng = _group(kind), np.random.default_rng(seed)
    dim = grp.dim
    # each message carries rows of agents no other message (nor the process itself) has
    taken = {START + r for r in local}
    messages, rows = [], {}
    for agents in senders:
        agents = [a for a in agents if a not in taken]
        if not agents:
            continue
        taken.update(agents)
        n = len(agents)
        msg = wire.StageRows(np.array(agents), 3, 1, 0, 0.5, _rotations(grp, n, rng),
                             rng.normal(size=(n, dim)) if with_x else None,
                             rng.normal(size=(n, dim)) if with_v else None)
        messages.append(msg)
        for r, a in enumerate(agents):
            if START <= a < START + SIZE:
                rows[a - START] = wire.Row(0.0 if msg.x is None else msg.x[r],
                                           grp.take(msg.rot, [r]),
                                           None if msg.v is None else msg.v[r])
    state = GroupState(rng.normal(size=(len(local), dim)), _rotations(grp, len(local), rng),
                       rng.normal(size=(len(local), dim)), None)
    own = (np.array(local, dtype=int), state) if local else None
    by_message = wire.assemble_rows(grp, dim, START, SIZE, messages, own, with_v=with_v)
    one_by_one = wire.assemble(grp, dim, rows, own, with_v=with_v)
    assert np.array_equal(by_message.index, one_by_one.index)
    assert np.array_equal(by_message.x, one_by_one.x)
    assert np.array_equal(grp.to_matrices(by_message.rot), grp.to_matrices(one_by_one.rot))
    assert (by_message.v is None) == (one_by_one.v is None)
    if with_v:
        assert np.array_equal(by_message.v, one_by_one.v)
