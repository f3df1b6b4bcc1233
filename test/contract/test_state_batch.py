"""A realtime tick's take of its peers' states, decoded together (``wire.decode_exchanges``).

The peers' states of a tick are checked with one array operation per check instead of one per
message; each message must still come out as if decoded alone: every way of refusing one
(the reasons of the exchange's contract, listed here by hand) is found with exactly its reason
wherever it sits in a batch of good ones, and the good ones keep the values written here
(rotations by scipy's ``Rotation``, W by hand).  Messages are built directly (no DDS).
"""

import math

import numpy as np
import pytest
from ros_harness import needs_ros
from scipy.spatial.transform import Rotation

pytestmark = needs_ros

RUN_ID, T_MAX = 77, 30.0
R3 = Rotation.from_rotvec([0.3, -0.2, 0.5]).as_matrix()
SPIN = np.array([[0.0, -0.5, 0.25], [0.5, 0.0, -1.0], [-0.25, 1.0, 0.0]])   # skew


def _flat(m):
    return [float(v) for v in np.asarray(m).ravel()]


def _rot(agent):
    """A rotation of its own for each agent (scipy), so rows cannot be mixed up unnoticed."""
    return Rotation.from_rotvec([0.1 * agent, -0.2, 0.05 * agent]).as_matrix()


def _state(agent, second=True, stamp=(1, 250_000_000), **changes):
    from polymatch_interfaces.msg import AgentState

    fields = dict(run_id=RUN_ID, agent=agent, centroid=[0.5 * agent, -1.0, 2.0],
                  rotation=_flat(_rot(agent)))
    if second:
        fields.update(velocity=[0.1, 0.2, -0.3 * agent], angular_velocity=_flat(agent * SPIN))
    msg = AgentState(**{**fields, **changes})
    msg.header.stamp.sec, msg.header.stamp.nanosec = stamp
    return msg


def _decode(pairs):
    from polymatch_ros.core.so import SO3
    from polymatch_ros.ros import wire

    return wire.decode_exchanges(pairs, SO3(), 3, RUN_ID, T_MAX)


BAD = [
    ("another run", {"run_id": RUN_ID + 1}, "unknown sender (run id)"),
    ("nanoseconds of a whole second", {"stamp": (1, 10**9)}, "malformed header"),
    ("stamped past t_end", {"stamp": (30, 2000)}, "stamp outside the run"),
    ("a short centroid", {"centroid": [0.5, -1.0]}, "malformed layout"),
    ("a velocity without angular velocity", {"angular_velocity": []}, "malformed layout"),
    ("NaN in the centroid", {"centroid": [math.nan, -1.0, 2.0]}, "non-finite value"),
    ("a velocity above 1e100", {"velocity": [0.1, 0.2, 1e101]}, "value out of range"),
    ("a tilted rotation", {"rotation": _flat(1.001 * R3)}, "rotation not in SO(d)"),
    ("a reflection", {"rotation": _flat(np.diag([-1.0, 1.0, 1.0]) @ R3)},
     "rotation not in SO(d)"),
    ("W not skew", {"angular_velocity": _flat(SPIN + np.diag([0.0, 0.0, 0.5]))},
     "angular velocity not skew"),
]


def _assert_good(agent, motion, reason, second=True):
    from polymatch_ros.core.so import SO3

    assert reason is None and (motion.t, motion.key) == (1.25, 1_250_000_000)
    assert motion.x.tolist() == [0.5 * agent, -1.0, 2.0]
    assert np.allclose(SO3().to_matrices(motion.rot)[0], _rot(agent), atol=1e-15)
    if second:
        assert motion.v.tolist() == [0.1, 0.2, -0.3 * agent]
        assert np.array_equal(SO3().algebra_to_skew(motion.w)[0], agent * SPIN)
    else:
        assert motion.v is None and motion.w is None


@pytest.mark.parametrize("where", [0, 2, 4])
@pytest.mark.parametrize("what,changes,reason", BAD, ids=[c[0] for c in BAD])
def test_a_bad_state_among_good_ones_is_dropped_alone_with_its_reason(what, changes, reason,
                                                                      where):
    agents = [3, 5, 6, 8, 11]
    pairs = [(a, _state(a, **(changes if i == where else {}))) for i, a in enumerate(agents)]
    got = _decode(pairs)
    assert [a for a, _, _ in got] == agents
    for i, (agent, motion, why) in enumerate(got):
        if i == where:
            assert (motion, why) == (None, reason)
        else:
            _assert_good(agent, motion, why)


def test_a_message_on_another_agents_reader_is_dropped():
    got = _decode([(3, _state(3)), (4, _state(9))])
    _assert_good(*got[0])
    assert got[1] == (4, None, "unknown sender (agent index)")


def test_first_and_second_order_states_in_one_take_are_each_read_as_they_are():
    got = _decode([(1, _state(1, second=False)), (2, _state(2)), (4, _state(4, second=False))])
    _assert_good(*got[0], second=False)
    _assert_good(*got[1])
    _assert_good(*got[2], second=False)


def test_nothing_taken_decodes_to_nothing():
    assert _decode([]) == []
