"""Every way a decoder of ``wire`` refuses a message, reached on purpose: one hand-made message
per rejection path of ``codec`` (stage and block messages), ``exchange`` (the run's own
states) and ``motion`` (poses and velocities), each dropped with its own reason.
test_wire_fuzz.py throws random messages at the same decoders; here no path depends on what the
fuzzer happens to draw.  Messages are built directly (no DDS)."""

import math

import numpy as np
import pytest
from ros_harness import needs_ros

pytestmark = needs_ros

RUN_ID, AGENT, T_MAX = 77, 3, 30.0
BLOCK, K = 2, 4                      # block 2 of 4 agents: agents 8 .. 11


def _group(dim):
    from polymatch_ros.core.so import SO2, SO3, SOn

    return {2: SO2(), 3: SO3()}.get(dim) or SOn(dim)


def _tilted(dim, amount=1e-3):
    """A matrix (1 + amount) I: orthogonality defect ~2 amount, far above ROTATION_TOL."""
    return ((1.0 + amount) * np.eye(dim)).ravel().tolist()


# -- stage and block messages (codec) ---------------------------------------------------------


def _stage_data():
    """A valid stage of agent 3, d = 3: header, x, rot (mask 5)."""
    return [2.0, RUN_ID, AGENT, 4.0, 1.0, 0.0, 1.25, 5.0] + [0.5, -1.0, 2.0] + _tilted(3, 0.0)


def _block_data():
    """A valid block message: agents 8 and 9 of block 2, x and rot (mask 5)."""
    rows = [[8.0, 0.5, -1.0, 2.0] + _tilted(3, 0.0), [9.0, 1.5, 0.0, -2.0] + _tilted(3, 0.0)]
    return [3.0, RUN_ID, BLOCK, 4.0, 1.0, 0.0, 1.25, 5.0] + rows[0] + rows[1]


def _array_msg(data, dims=(), offset=0):
    from std_msgs.msg import Float64MultiArray, MultiArrayDimension

    msg = Float64MultiArray()
    msg.layout.dim = [MultiArrayDimension(label=label, size=size, stride=size)
                      for label, size in dims]
    msg.layout.data_offset = offset
    msg.data = [float(v) for v in data]
    return msg


def _set(data, index, value):
    data = list(data)
    data[index] = value
    return data


HEADER_CASES = [  # (what, index in the header, value, reason): the same for stages and blocks
    ("format", 0, 9.0, "unknown format"),
    ("run id", 1, RUN_ID + 1.0, "unknown sender (run id)"),
    ("negative run id", 1, -1.0, "malformed header"),
    ("fractional step", 3, 4.5, "malformed header"),
    ("negative stage", 4, -1.0, "malformed header"),
    ("negative flags", 5, -1.0, "malformed header"),
    ("fractional mask", 7, 5.5, "malformed header"),
    ("step beyond 2^53", 3, 2.0 ** 54, "malformed header"),
    ("time beyond 2^53", 6, 2.0 ** 54, "malformed header"),
    ("negative time", 6, -0.5, "stamp outside the run"),
    ("time past t_end", 6, T_MAX + 2e-6, "stamp outside the run"),
    ("NaN in the header", 6, math.nan, "non-finite value"),
    ("infinity in the header", 3, math.inf, "non-finite value"),
    ("huge header value", 5, 1e101, "value out of range"),
]

STAGE_CASES = HEADER_CASES + [
    ("agent index", 2, AGENT + 1.0, "unknown sender (agent index)"),
    ("NaN in x", 8, math.nan, "non-finite value"),
    ("-infinity in rot", 12, -math.inf, "non-finite value"),
    ("x beyond MAX_ABS", 9, 1e101, "value out of range"),
    ("unknown mask bit", 7, 13.0, "malformed layout"),
    ("mask without rot", 7, 1.0, "malformed layout"),
    ("mask x, v, rot without v", 7, 7.0, "malformed layout"),
    ("rot not orthogonal", 11, 1.001, "rotation not orthogonal"),
]

BLOCK_CASES = HEADER_CASES + [
    ("block index", 2, BLOCK + 1.0, "unknown sender (agent index)"),
    ("fractional agent", 8, 8.5, "unknown sender (agent index)"),
    ("agent below the block", 8, 7.0, "unknown sender (agent index)"),
    ("agent past the block", 8, 12.0, "unknown sender (agent index)"),
    ("agent twice", 8 + 13, 8.0, "unknown sender (agent index)"),
    ("NaN in a row", 9, math.nan, "non-finite value"),
    ("row value beyond MAX_ABS", 8 + 13 + 2, -1e101, "value out of range"),
    ("unknown mask bit", 7, 12.0 + 1.0, "malformed layout"),
    ("mask without rot", 7, 1.0, "malformed layout"),
    ("rot of the second row not orthogonal", 8 + 13 + 4, 1.001, "rotation not orthogonal"),
]


def _decode_stage(msg):
    from polymatch_ros.ros import wire

    return wire.decode_stage(msg, _group(3), 3, RUN_ID, AGENT, wire.ROTATION_TOL, T_MAX)


def _decode_block(msg):
    from polymatch_ros.ros import wire

    return wire.decode_block(msg, _group(3), 3, RUN_ID, BLOCK, K, wire.ROTATION_TOL, T_MAX)


def test_the_unchanged_stage_and_block_messages_are_accepted():
    stage, reason = _decode_stage(_array_msg(_stage_data()))
    assert reason is None and (stage.agent, stage.step, stage.stage, stage.t) == (3, 4, 1, 1.25)
    rows, reason = _decode_block(_array_msg(_block_data()))
    assert reason is None and rows.agents.tolist() == [8, 9] and rows.x.shape == (2, 3)
    edge = _set(_stage_data(), 6, T_MAX + 1e-7)            # within STAMP_SLACK of t_end
    assert _decode_stage(_array_msg(edge))[1] is None


@pytest.mark.parametrize("what,index,value,reason", STAGE_CASES, ids=[c[0] for c in STAGE_CASES])
def test_stage_message_is_dropped_with_its_reason(what, index, value, reason):
    assert _decode_stage(_array_msg(_set(_stage_data(), index, value))) == (None, reason)


@pytest.mark.parametrize("what,index,value,reason", BLOCK_CASES, ids=[c[0] for c in BLOCK_CASES])
def test_block_message_is_dropped_with_its_reason(what, index, value, reason):
    assert _decode_block(_array_msg(_set(_block_data(), index, value))) == (None, reason)


@pytest.mark.parametrize("decode,data", [(_decode_stage, _stage_data),
                                         (_decode_block, _block_data)], ids=["stage", "block"])
def test_malformed_layouts_are_dropped(decode, data):
    """Shorter than a header, with layout dims or an offset, a body of the wrong length."""
    full = data()
    for msg in (_array_msg(full[:7]), _array_msg([]), _array_msg(full, dims=[("t", 1)]),
                _array_msg(full, offset=1), _array_msg(full[:-1]), _array_msg(full + [0.0])):
        assert decode(msg) == (None, "malformed layout")


def test_a_block_without_rows_or_with_too_many_is_dropped():
    assert _decode_block(_array_msg(_block_data()[:8])) == (None, "malformed layout")
    rows = [[float(a), 0.0, 0.0, 0.0] + _tilted(3, 0.0) for a in (8, 9, 10, 11, 8)]
    data = _block_data()[:8] + [v for row in rows for v in row]
    assert _decode_block(_array_msg(data)) == (None, "unknown sender (agent index)")


# -- poses and velocities (motion) ------------------------------------------------------------


def _pose(dim, x=None, quat=None, frame="world", stamp=(1, 0)):
    from geometry_msgs.msg import PoseStamped

    msg = PoseStamped()
    msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = x or (0.5, -1.0, 0.0)
    o = msg.pose.orientation
    o.x, o.y, o.z, o.w = quat or (0.0, 0.0, math.sin(0.2), math.cos(0.2))
    msg.header.frame_id = frame
    msg.header.stamp.sec, msg.header.stamp.nanosec = stamp
    return msg


def _twist(dim, lin=None, ang=None, frame="world", stamp=(1, 0)):
    from geometry_msgs.msg import TwistStamped

    msg = TwistStamped()
    msg.twist.linear.x, msg.twist.linear.y, msg.twist.linear.z = lin or (0.5, -1.0, 0.0)
    msg.twist.angular.x, msg.twist.angular.y, msg.twist.angular.z = ang or (0.0, 0.0, 0.3)
    msg.header.frame_id = frame
    msg.header.stamp.sec, msg.header.stamp.nanosec = stamp
    return msg


HALF = math.sqrt(0.5)
GEOMETRY_CASES = [  # (what, kind, dimension, message fields, reason)
    ("NaN position", "pose", 3, {"x": (math.nan, 0.0, 0.0)}, "non-finite value"),
    ("infinite quaternion", "pose", 3, {"quat": (0.0, 0.0, 0.0, math.inf)}, "non-finite value"),
    ("position beyond MAX_ABS", "pose", 3, {"x": (0.0, 1e101, 0.0)}, "value out of range"),
    ("quaternion of norm 1.001", "pose", 3, {"quat": (0.0, 0.0, 0.0, 1.001)},
     "quaternion far from unit norm"),
    ("quaternion of norm 0", "pose", 3, {"quat": (0.0, 0.0, 0.0, 0.0)},
     "quaternion far from unit norm"),
    ("2-D pose off the plane", "pose", 2, {"x": (0.0, 0.0, 0.5)}, "not a planar pose"),
    ("2-D pose tilted about x", "pose", 2, {"quat": (HALF, 0.0, 0.0, HALF)}, "not a planar pose"),
    ("2-D pose tilted about y", "pose", 2, {"quat": (0.0, HALF, 0.0, HALF)}, "not a planar pose"),
    ("pose in another frame", "pose", 3, {"frame": "map"}, "unknown frame 'map'"),
    ("pose nanoseconds of a whole second", "pose", 3, {"stamp": (1, 10**9)}, "malformed header"),
    ("pose stamped past t_end", "pose", 3, {"stamp": (30, 2000)}, "stamp outside the run"),
    ("corrupt contents named before the frame", "pose", 3,
     {"x": (math.nan, 0.0, 0.0), "frame": "map"}, "non-finite value"),
    ("NaN angular velocity", "twist", 3, {"ang": (0.0, math.nan, 0.0)}, "non-finite value"),
    ("-infinite velocity", "twist", 2, {"lin": (-math.inf, 0.0, 0.0)}, "non-finite value"),
    ("velocity beyond MAX_ABS", "twist", 3, {"lin": (0.0, 0.0, -1e101)}, "value out of range"),
    ("2-D velocity off the plane", "twist", 2, {"lin": (0.0, 0.0, 1.0)},
     "not a planar velocity"),
    ("2-D angular velocity about x", "twist", 2, {"ang": (1.0, 0.0, 0.3)},
     "not a planar velocity"),
    ("2-D angular velocity about y", "twist", 2, {"ang": (0.0, 1.0, 0.3)},
     "not a planar velocity"),
    ("twist in another frame", "twist", 3, {"frame": ""}, "unknown frame ''"),
    ("twist nanoseconds of a whole second", "twist", 2, {"stamp": (0, 10**9)},
     "malformed header"),
    ("twist stamped past t_end", "twist", 3, {"stamp": (31, 0)}, "stamp outside the run"),
]


def _decode_geometry(kind, dim, msg):
    from polymatch_ros.ros import wire

    decode = wire.decode_pose_msg if kind == "pose" else wire.decode_twist_msg
    return decode(msg, _group(dim), dim, "world", T_MAX)


@pytest.mark.parametrize("kind", ["pose", "twist"])
@pytest.mark.parametrize("dim", [2, 3])
def test_the_unchanged_geometry_messages_are_accepted(kind, dim):
    msg = (_pose if kind == "pose" else _twist)(dim)
    got, reason = _decode_geometry(kind, dim, msg)
    assert reason is None and got.t == 1.0 and np.allclose(got.vec, [0.5, -1.0, 0.0][:dim])


@pytest.mark.parametrize("what,kind,dim,fields,reason", GEOMETRY_CASES,
                         ids=[c[0] for c in GEOMETRY_CASES])
def test_geometry_message_is_dropped_with_its_reason(what, kind, dim, fields, reason):
    msg = (_pose if kind == "pose" else _twist)(dim, **fields)
    assert _decode_geometry(kind, dim, msg) == (None, reason)


def _motion_array(kind, matrix=None, t=1.0, vec=(0.5, -1.0, 2.0, 0.0), dims=3, offset=0):
    """A d = 4 pose (identity rotation) or twist (a skew matrix) as a Float64MultiArray."""
    if matrix is None:
        skew = np.zeros((4, 4))
        skew[0, 1], skew[1, 0] = -0.3, 0.3
        matrix = np.eye(4).ravel().tolist() if kind == "pose" else skew.ravel().tolist()
    labels = [("t", 1), ("v", 4), ("m", 16), ("extra", 1)][:dims]
    return _array_msg([t, *vec, *matrix], dims=labels, offset=offset)


REFLECTION = np.diag([-1.0, 1.0, 1.0, 1.0]).ravel().tolist()
ARRAY_CASES = [  # (what, kind, message arguments, reason)
    ("two layout dims", "pose", {"dims": 2}, "malformed layout"),
    ("four layout dims", "twist", {"dims": 4}, "malformed layout"),
    ("a data offset", "pose", {"offset": 1}, "malformed layout"),
    ("a short centroid", "pose", {"vec": (0.5, -1.0, 2.0)}, "malformed layout"),
    ("a long velocity", "twist", {"vec": (0.5, -1.0, 2.0, 0.0, 1.0)}, "malformed layout"),
    ("NaN centroid", "pose", {"vec": (0.5, math.nan, 2.0, 0.0)}, "non-finite value"),
    ("infinite stamp", "twist", {"t": math.inf}, "non-finite value"),
    ("centroid beyond MAX_ABS", "pose", {"vec": (0.5, 1e101, 2.0, 0.0)}, "value out of range"),
    ("rotation not orthogonal", "pose", {"matrix": _tilted(4)}, "rotation not in SO(d)"),
    ("a reflection", "pose", {"matrix": REFLECTION}, "rotation not in SO(d)"),
    ("angular velocity not skew", "twist", {"matrix": np.eye(4).ravel().tolist()},
     "angular velocity not skew"),
    ("negative stamp", "pose", {"t": -0.5}, "stamp outside the run"),
    ("stamp past t_end", "twist", {"t": T_MAX + 2e-6}, "stamp outside the run"),
]


@pytest.mark.parametrize("kind", ["pose", "twist"])
def test_the_unchanged_array_messages_are_accepted(kind):
    got, reason = _decode_geometry(kind, 4, _motion_array(kind))
    assert reason is None and got.t == 1.0 and np.allclose(got.vec, [0.5, -1.0, 2.0, 0.0])


@pytest.mark.parametrize("what,kind,arguments,reason", ARRAY_CASES,
                         ids=[c[0] for c in ARRAY_CASES])
def test_array_message_is_dropped_with_its_reason(what, kind, arguments, reason):
    assert _decode_geometry(kind, 4, _motion_array(kind, **arguments)) == (None, reason)


# -- the run's exchange (wire.exchange) -------------------------------------------------------

SPIN = [[0.0, -0.5, 0.25], [0.5, 0.0, -1.0], [-0.25, 1.0, 0.0]]  # W_i, skew


def _exchange_data():
    """A valid second-order exchange of agent 3, d = 3: header, x, v, rot, W (mask 15)."""
    return ([4.0, RUN_ID, AGENT, 0.0, 0.0, 0.0, 1.25, 15.0] + [0.5, -1.0, 2.0]
            + [0.1, 0.2, -0.3] + _tilted(3, 0.0) + [w for row in SPIN for w in row])


def _decode_exchange(msg):
    from polymatch_ros.ros import wire

    return wire.decode_exchange(msg, _group(3), 3, RUN_ID, AGENT, T_MAX)


X, V, ROT, W = 8, 11, 14, 23  # where each field starts in _exchange_data
EXCHANGE_CASES = HEADER_CASES + [
    ("a stage message's format", 0, 2.0, "unknown format"),
    ("another run", 1, 12345.0, "unknown sender (run id)"),
    ("agent index", 2, AGENT + 1.0, "unknown sender (agent index)"),
    ("NaN in x", X, math.nan, "non-finite value"),
    ("infinity in W", W + 1, math.inf, "non-finite value"),
    ("v beyond MAX_ABS", V, 1e101, "value out of range"),
    ("unknown mask bit", 7, 31.0, "malformed layout"),
    ("mask without rot", 7, 11.0, "malformed layout"),
    ("mask v without W", 7, 7.0, "malformed layout"),
    ("mask W without v", 7, 13.0, "malformed layout"),
    ("rotation not orthogonal", ROT, 1.001, "rotation not in SO(d)"),
    ("W not skew", W, 0.5, "angular velocity not skew"),
]


def test_an_exchange_message_round_trips_and_is_accepted():
    """What an agent publishes (encode_exchange) reads back as it was; the hand-made message
    is accepted with its fields in place."""
    from std_msgs.msg import Float64MultiArray

    from polymatch_ros.ros import wire

    grp = _group(3)
    rot = grp.from_matrices(np.eye(3)[None])
    w = grp.algebra_from_skew(np.array(SPIN)[None])
    msg = wire.encode_exchange(Float64MultiArray(), grp, RUN_ID, AGENT, 1.25,
                               np.array([0.5, -1.0, 2.0]), rot, np.array([0.1, 0.2, -0.3]), w)
    assert list(msg.data) == _exchange_data()
    got, reason = _decode_exchange(_array_msg(_exchange_data()))
    assert reason is None and (got.t, got.key) == (1.25, 1_250_000_000)
    assert got.x.tolist() == [0.5, -1.0, 2.0] and got.v.tolist() == [0.1, 0.2, -0.3]
    assert np.array_equal(grp.algebra_to_skew(got.w)[0], SPIN)
    first = _exchange_data()[:V] + _tilted(3, 0.0)     # first order: x and rot (mask 5)
    got, reason = _decode_exchange(_array_msg(_set(first, 7, 5.0)))
    assert reason is None and got.v is None and got.w is None


@pytest.mark.parametrize("sender,reader", [("matrix", "angle"), ("angle", "matrix")])
def test_an_exchange_is_read_in_the_readers_own_representation(sender, reader):
    """A 2-D projection integrator's agents compute with matrices, the monitor and the runner
    with angles (``core.simulate.prepare``): the exchange carries the matrix, and each side
    reads the other's rotation as its own, to an ulp."""
    from std_msgs.msg import Float64MultiArray

    from polymatch_ros.core.so import SO2, SOn
    from polymatch_ros.ros import wire

    groups = {"angle": SO2(), "matrix": SOn(2)}
    angle = 2.5
    rot = groups[sender].from_matrices(SO2().to_matrices(np.array([angle])))
    msg = wire.encode_exchange(Float64MultiArray(), groups[sender], RUN_ID, AGENT, 1.25,
                               np.array([0.5, -1.0]), rot)
    assert len(msg.data) == 8 + 2 + 4
    got, reason = wire.decode_exchange(msg, groups[reader], 2, RUN_ID, AGENT, T_MAX)
    assert reason is None
    back = SO2().from_matrices(groups[reader].to_matrices(got.rot))
    assert abs(back[0] - angle) <= 4e-16


@pytest.mark.parametrize("what,index,value,reason", EXCHANGE_CASES,
                         ids=[c[0] for c in EXCHANGE_CASES])
def test_exchange_message_is_dropped_with_its_reason(what, index, value, reason):
    assert _decode_exchange(_array_msg(_set(_exchange_data(), index, value))) == (None, reason)


def test_an_exchange_with_a_reflection_or_the_wrong_length_is_dropped():
    reflection = _exchange_data()
    reflection[ROT:ROT + 9] = np.diag([-1.0, 1.0, 1.0]).ravel().tolist()
    assert _decode_exchange(_array_msg(reflection)) == (None, "rotation not in SO(d)")
    full = _exchange_data()
    for msg in (_array_msg(full[:-1]), _array_msg(full + [0.0]), _array_msg(full[:7]),
                _array_msg(full, dims=[("t", 1)])):
        assert _decode_exchange(msg) == (None, "malformed layout")


# -- the exchange of a packed lockstep process (one message a block and step) -----------------


def _exchange_block_data():
    """A valid second-order exchange block: agents 8 and 9 of block 2, each row as agent 3's
    exchange above (x, v, rot, W; mask 15)."""
    row = _exchange_data()[HEADER_LEN:]
    return [5.0, RUN_ID, BLOCK, 0.0, 0.0, 0.0, 1.25, 15.0] + [8.0] + row + [9.0] + row


HEADER_LEN, ROW = 8, 1 + 3 + 3 + 9 + 9  # a row: agent, x, v, rot, W
EXCHANGE_BLOCK_CASES = HEADER_CASES + [
    ("an exchange's format", 0, 4.0, "unknown format"),
    ("block index", 2, BLOCK + 1.0, "unknown sender (agent index)"),
    ("agent past the block", HEADER_LEN + ROW, 12.0, "unknown sender (agent index)"),
    ("agent twice", HEADER_LEN + ROW, 8.0, "unknown sender (agent index)"),
    ("NaN in the second row's x", HEADER_LEN + ROW + 1, math.nan, "non-finite value"),
    ("mask v without W", 7, 7.0, "malformed layout"),
    ("second row's rotation not orthogonal", HEADER_LEN + ROW + 7, 1.001,
     "rotation not in SO(d)"),
    ("second row's W not skew", HEADER_LEN + ROW + 16, 0.5, "angular velocity not skew"),
]


def _decode_exchange_block(msg):
    from polymatch_ros.ros import wire

    return wire.decode_exchange_block(msg, _group(3), 3, RUN_ID, BLOCK, K, T_MAX)


def test_an_exchange_block_reads_as_its_agents_own_exchanges():
    """What a packed process publishes (encode_exchange_block) gives the monitor, row by row,
    the numbers each agent's own exchange message would give: bit for bit."""
    from std_msgs.msg import Float64MultiArray

    from polymatch_ros.ros import wire

    grp = _group(3)
    msg = wire.encode_exchange_block(
        Float64MultiArray(), grp, RUN_ID, BLOCK, 1.25, [8, 9], np.array([[0.5, -1.0, 2.0]] * 2),
        grp.from_matrices(np.stack([np.eye(3)] * 2)), np.array([[0.1, 0.2, -0.3]] * 2),
        grp.algebra_from_skew(np.array([SPIN] * 2)))
    assert list(msg.data) == _exchange_block_data()
    rows, reason = _decode_exchange_block(msg)
    one, _ = _decode_exchange(_array_msg(_exchange_data()))
    assert reason is None and [a for a, _ in rows] == [8, 9]
    for _, got in rows:
        assert (got.t, got.key) == (one.t, one.key)
        for field in ("x", "rot", "v", "w"):
            assert np.array_equal(getattr(got, field), getattr(one, field))


@pytest.mark.parametrize("what,index,value,reason", EXCHANGE_BLOCK_CASES,
                         ids=[c[0] for c in EXCHANGE_BLOCK_CASES])
def test_exchange_block_is_dropped_whole_with_its_reason(what, index, value, reason):
    data = _set(_exchange_block_data(), index, value)
    assert _decode_exchange_block(_array_msg(data)) == (None, reason)


def test_an_exchange_block_with_a_reflection_or_the_wrong_length_is_dropped():
    reflection = _exchange_block_data()
    start = HEADER_LEN + ROW + 7
    reflection[start:start + 9] = np.diag([-1.0, 1.0, 1.0]).ravel().tolist()
    assert _decode_exchange_block(_array_msg(reflection)) == (None, "rotation not in SO(d)")
    full = _exchange_block_data()
    for msg in (_array_msg(full[:-1]), _array_msg(full[:HEADER_LEN]), _array_msg(full[:7]),
                _array_msg(full, dims=[("t", 1)])):
        assert _decode_exchange_block(msg) == (None, "malformed layout")
