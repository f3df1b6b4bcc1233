"""Never poisoned from the wire: every decoder of ``wire`` either accepts a message - and then
its values are finite, bounded and its rotation is in SO(d) (Lemma 2.1) - or drops it with a
counted reason.  It never raises.  Messages are built directly (no DDS).

Each fuzzer first runs explicit examples (``@example``): a valid message of each shape it
draws, accepted, and one message per way it is dropped; random draws follow.
test_wire_rejections.py asserts each of those reasons on hand-made messages.
"""

import math

import numpy as np
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from ros_harness import needs_ros

pytestmark = needs_ros

# 50 random messages per fuzzer (a new draw each run), after its explicit examples: those
# reach every outcome five runs of 200 random ones reached, and acceptance, which the stage,
# block and pose fuzzers almost never drew.
SETTINGS = settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.too_slow])
T_MAX = 30.0
RUN_ID = 77
NAN, INF = math.nan, math.inf


def _group(dim, angle=False):
    """The core's rotation representations: an angle (d = 2), SO(3), a d x d matrix."""
    from polymatch_ros.core.so import SO2, SO3, SOn

    if angle and dim == 2:
        return SO2()
    return SO3() if dim == 3 else SOn(dim)


_matrix_group = _group


floats = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True, width=64),
    st.sampled_from(
        [
            0.0,
            -0.0,
            5e-324,
            -5e-324,
            1e-310,
            1e308,
            -1e308,
            1.0,
            -1.0,
            0.5,
            math.nan,
            math.inf,
            -math.inf,
            1e101,
            0.7071067811865476,
        ]
    ),
)


class Counter:
    def __init__(self):
        self.reasons = {}

    def __call__(self, reason):
        assert isinstance(reason, str) and reason
        self.reasons[reason] = self.reasons.get(reason, 0) + 1


def _with_examples(cases):
    """Decorate a fuzzer with the explicit examples ``cases`` (keyword arguments each)."""
    def decorate(test):
        for case in reversed(cases):
            test = example(**case)(test)
        return test
    return decorate


def _rotation(dim, seed):
    """A rotation in SO(dim) from ``seed``: Q of a Gaussian matrix's QR, its columns' signs set
    by R's diagonal (Haar, as scipy's special_ortho_group draws), one flipped if det < 0."""
    q, r = np.linalg.qr(np.random.default_rng(seed).normal(size=(dim, dim)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


def _check_rotation(grp, rot):
    mats = grp.to_matrices(rot)
    assert np.all(np.isfinite(mats))
    for m in mats:
        assert np.max(np.abs(m.T @ m - np.eye(len(m)))) < 1e-8 and np.linalg.det(m) > 0


def _accepted_or_counted(result, counter, check):
    value, reason = result
    if value is None:
        counter(reason)
    else:
        assert reason is None
        check(value)


def _check_received(grp, dim, rotation):
    from polymatch_ros.ros import wire

    def check(got):
        assert 0.0 <= got.t <= T_MAX + wire.STAMP_SLACK
        assert got.vec.shape == (dim,) and np.all(np.isfinite(got.vec))
        assert np.max(np.abs(got.vec)) <= wire.MAX_ABS
        if rotation:
            _check_rotation(grp, got.rot)
        else:
            assert np.all(np.isfinite(grp.algebra_to_skew(got.rot)))

    return check


def _stamp_and_decode(msg, decoder, dim, stamp, frame, rotation):
    """Stamp a geometry_msgs *Stamped message, decode it with ``wire.<decoder>`` (SO(d) as
    matrices, frame "world") and check it is accepted valid or dropped with a counted reason."""
    from polymatch_ros.ros import wire

    grp = _matrix_group(dim)
    msg.header.frame_id = frame
    msg.header.stamp.sec, msg.header.stamp.nanosec = stamp
    decode = getattr(wire, decoder)
    _accepted_or_counted(decode(msg, grp, dim, "world", T_MAX), Counter(),
                         _check_received(grp, dim, rotation))


stamps = st.tuples(
    st.integers(0, 2**31 - 1) | st.sampled_from([0, 1, 29, 30, 31, 10**9]),
    st.integers(0, 2**32 - 1) | st.sampled_from([0, 999_999_999, 10**9]),
)
frames = st.sampled_from(["world", "world", "map", "", "World"])
QUAT = (0.0, 0.0, math.sin(0.2), math.cos(0.2))   # a turn about z: planar


def _geometry_cases(vector, rotation, valid, off_plane):
    """Explicit examples of a pose or twist fuzzer: ``vector`` and ``rotation`` name its two
    parts, ``valid`` their valid values; accepted in 3-D and 2-D, then one of each outcome."""
    def case(dim=3, stamp=(1, 0), frame="world", **parts):
        return {"dim": dim, vector: valid[0], rotation: valid[1], "stamp": stamp,
                "frame": frame, **parts}

    return [case(), case(dim=2, stamp=(29, 999_999_999)),
            case(**{vector: (NAN, 0.0, 0.0)}), case(**{rotation: valid[1][:-1] + (INF,)}),
            case(**{vector: (0.0, 1e101, 0.0)}), case(dim=2, **{vector: (0.0, 0.0, 0.5)}),
            case(dim=2, **{rotation: off_plane}), case(frame="map"), case(frame=""),
            case(frame="World"), case(stamp=(1, 10**9)), case(stamp=(31, 0))]


POSE_CASES = _geometry_cases("pos", "quat", ((0.5, -1.0, 0.0), QUAT), (0.6, 0.0, 0.0, 0.8))
POSE_CASES.append(POSE_CASES[0] | {"quat": (0.0, 0.0, 0.0, 1.001)})   # far from unit norm


@SETTINGS
@given(
    dim=st.sampled_from([2, 3]),
    pos=st.tuples(floats, floats, floats),
    quat=st.one_of(st.tuples(floats, floats, floats, floats),
                   st.tuples(*[st.floats(-1, 1)] * 4)),
    stamp=stamps,
    frame=frames,
)
@_with_examples(POSE_CASES)
def test_pose_stamped_is_accepted_valid_or_dropped(dim, pos, quat, stamp, frame):
    from geometry_msgs.msg import PoseStamped

    msg = PoseStamped()
    p, o = msg.pose.position, msg.pose.orientation
    p.x, p.y, p.z = pos
    o.x, o.y, o.z, o.w = quat
    _stamp_and_decode(msg, "decode_pose_msg", dim, stamp, frame, rotation=True)


TWIST_CASES = _geometry_cases("lin", "ang", ((0.5, -1.0, 0.0), (0.0, 0.0, 0.3)),
                              (1.0, 0.0, 0.3))


@SETTINGS
@given(
    dim=st.sampled_from([2, 3]),
    lin=st.tuples(floats, floats, floats),
    ang=st.tuples(floats, floats, floats),
    stamp=stamps,
    frame=frames,
)
@_with_examples(TWIST_CASES)
def test_twist_stamped_is_accepted_valid_or_dropped(dim, lin, ang, stamp, frame):
    from geometry_msgs.msg import TwistStamped

    msg = TwistStamped()
    msg.twist.linear.x, msg.twist.linear.y, msg.twist.linear.z = lin
    msg.twist.angular.x, msg.twist.angular.y, msg.twist.angular.z = ang
    _stamp_and_decode(msg, "decode_twist_msg", dim, stamp, frame, rotation=False)


def _array(data, dims):
    from std_msgs.msg import Float64MultiArray, MultiArrayDimension

    msg = Float64MultiArray()
    msg.layout.dim = [
        MultiArrayDimension(label=label, size=size, stride=size) for label, size in dims
    ]
    msg.data = data
    return msg


def _array_case(data=(1.0, 0.5, -1.0, 2.0, 0.0, 3.0), dim=4, ndims=3, valid_rotation=True,
                kind="pose"):
    return {"dim": dim, "data": list(data), "ndims": ndims, "valid_rotation": valid_rotation,
            "seed": 7, "kind": kind}


ARRAY_CASES = [
    _array_case(), _array_case(dim=5, kind="twist"), _array_case(ndims=2),
    _array_case(data=(NAN,)), _array_case(data=(1.0, 0.0, -1e101)), _array_case(data=(31.0,)),
    _array_case(data=[1.0] + [0.0] * 20, valid_rotation=False),        # a zero matrix
    _array_case(data=[1.0] + [0.0] * 4 + np.eye(4).ravel().tolist(), valid_rotation=False,
                kind="twist"),                                         # I is not skew
]


@SETTINGS
@given(
    dim=st.sampled_from([4, 5]),
    data=st.lists(floats, max_size=40),
    ndims=st.integers(0, 4),
    valid_rotation=st.booleans(),
    seed=st.integers(0, 2**16),
    kind=st.sampled_from(["pose", "twist"]),
)
@_with_examples(ARRAY_CASES)
def test_float64_multiarray_poses_are_accepted_valid_or_dropped(
    dim, data, ndims, valid_rotation, seed, kind
):
    from polymatch_ros.ros import wire

    grp = _matrix_group(dim)
    if valid_rotation:  # a well-formed message, perturbed by the fuzzed values
        mat = _rotation(dim, seed)
        if kind == "twist":
            mat = mat - mat.T
        head = (data + [0.0] * (1 + dim))[: 1 + dim]
        data = head + mat.ravel().tolist()
    msg = _array(data, [("t", 1), ("v", dim), ("m", dim * dim), ("x", 1)][:ndims])
    counter = Counter()
    decode = wire.decode_pose_msg if kind == "pose" else wire.decode_twist_msg
    _accepted_or_counted(
        decode(msg, grp, dim, None, T_MAX),
        counter,
        _check_received(grp, dim, rotation=kind == "pose"),
    )


EYE3 = np.eye(3).ravel().tolist()
STAGE_HEADER = [2.0, float(RUN_ID), 3.0, 4.0, 1.0, 0.0, 1.25, 5.0]   # agent 3: x and rot


def _changed(values, index, value):
    values = list(values)
    values[index] = value
    return values


def _stage_case(header=STAGE_HEADER, body=(0.5, -1.0, 2.0, *EYE3), dim=3, angle=False,
                mask=None, well_formed=False):
    return {"dim": dim, "angle": angle, "header": list(header), "body": list(body),
            "mask": mask, "well_formed": well_formed}


HEADER_CHANGES = [(0, 9.0), (1, RUN_ID + 1.0), (3, 4.5), (6, 31.0)]   # format, run, step, time


def _headers(*typical):
    """Eight header fields: any floats, or values near a valid header's (``typical``, then
    step, stage, flags and ones that no header holds)."""
    return st.lists(floats | st.sampled_from([*typical, 4.0, 7.0, 5.0, -1.0, 2.5]),
                    min_size=8, max_size=8)

STAGE_CASES = [
    _stage_case(), _stage_case(STAGE_HEADER[:7] + [7.0], (0.5, -1.0, 0.1, 0.2, 0.3), dim=2,
                               angle=True),                            # x, v, angle
    _stage_case(body=(NAN,) + (0.0,) * 11), _stage_case(body=(1e101,) + (0.0,) * 11),
    _stage_case(_changed(STAGE_HEADER, 2, 4.0)), _stage_case(mask=12),
    _stage_case(body=(0.5, -1.0, 2.0, *(1.001 * np.eye(3)).ravel())),  # not orthogonal
] + [_stage_case(_changed(STAGE_HEADER, i, v)) for i, v in HEADER_CHANGES]


@SETTINGS
@given(
    dim=st.sampled_from([2, 3]),
    angle=st.booleans(),
    header=_headers(2.0, float(RUN_ID), 3.0),
    body=st.lists(floats, max_size=14),
    mask=st.sampled_from([None, 4, 5, 7, 6, 3, 12, 4.5]),
    well_formed=st.booleans(),
)
@_with_examples(STAGE_CASES)
def test_stage_messages_are_accepted_valid_or_dropped(dim, angle, header, body, mask, well_formed):
    from std_msgs.msg import Float64MultiArray

    from polymatch_ros.ros import wire

    grp = _group(dim, angle)
    if well_formed:
        header[:3] = [2.0, float(RUN_ID), 3.0]
    if mask is not None:
        header[7] = float(mask)
    msg = Float64MultiArray()
    msg.data = header + body
    counter = Counter()

    def check(stage):
        assert stage.agent == 3 and stage.step >= 0 and stage.stage >= 0
        assert 0.0 <= stage.t <= T_MAX + wire.STAMP_SLACK
        for v in (stage.x, stage.v):
            assert v is None or (v.shape == (dim,) and np.all(np.isfinite(v)))
        _check_rotation(grp, stage.rot)

    _accepted_or_counted(
        wire.decode_stage(msg, grp, dim, RUN_ID, 3, wire.ROTATION_TOL, T_MAX), counter, check
    )


BLOCK, K = 2, 4  # block 2 of 4 agents: agents 8 .. 11
BLOCK_HEADER = [3.0, float(RUN_ID), float(BLOCK), 4.0, 1.0, 0.0, 1.25, 5.0]   # x and rot
ROWS = [0.5, -1.0, 2.0, *EYE3, 1.5, 0.0, -2.0, *EYE3]                       # two rows' fields


def _block_case(header=BLOCK_HEADER, agents=(8.0, 9.0), body=ROWS, dim=3, angle=False,
                mask=None, well_formed=False):
    return {"dim": dim, "angle": angle, "header": list(header), "agents": list(agents),
            "body": list(body), "mask": mask, "well_formed": well_formed}


BLOCK_CASES = [
    _block_case(), _block_case(_changed(BLOCK_HEADER, 7, 4.0), (11.0, 8.0, 10.0),
                               (0.1, 0.2, 0.3), dim=2, angle=True),    # three angles
    _block_case(body=_changed(ROWS, 0, NAN)), _block_case(body=_changed(ROWS, 14, -1e101)),
    _block_case(agents=(7.0, 8.0)), _block_case(agents=(9.0, 9.0)), _block_case(mask=12),
    _block_case(body=_changed(ROWS, 16, 1.001)),                         # not orthogonal
] + [_block_case(_changed(BLOCK_HEADER, i, v)) for i, v in HEADER_CHANGES]


@SETTINGS
@given(
    dim=st.sampled_from([2, 3]),
    angle=st.booleans(),
    header=_headers(3.0, float(RUN_ID), float(BLOCK)),
    agents=st.lists(st.sampled_from([8.0, 9.0, 11.0, 7.0, 12.0, 8.5, -1.0]), max_size=5),
    body=st.lists(floats, max_size=30),
    mask=st.sampled_from([None, 4, 5, 7, 6, 3, 12, 4.5]),
    well_formed=st.booleans(),
)
@_with_examples(BLOCK_CASES)
def test_block_messages_are_accepted_valid_or_dropped(dim, angle, header, agents, body, mask,
                                                      well_formed):
    """A packed process's message of several agents' stage rows: every row valid, in the
    block and once, or the whole message dropped with a counted reason."""
    from std_msgs.msg import Float64MultiArray

    from polymatch_ros.ros import wire

    grp = _group(dim, angle)
    if well_formed:
        header[:3] = [3.0, float(RUN_ID), float(BLOCK)]
    if mask is not None:
        header[7] = float(mask)
    width = len(body) // max(1, len(agents))
    rows = [[a] + body[i * width:(i + 1) * width] for i, a in enumerate(agents)]
    msg = Float64MultiArray()
    msg.data = header + [v for row in rows for v in row]
    counter = Counter()

    def check(rows):
        agents = rows.agents.tolist()
        assert 1 <= len(agents) <= K and len(set(agents)) == len(agents)
        assert all(BLOCK * K <= a < (BLOCK + 1) * K for a in agents)
        assert rows.step >= 0 and rows.stage >= 0 and 0.0 <= rows.t <= T_MAX + wire.STAMP_SLACK
        for v in (rows.x, rows.v):
            assert v is None or (v.shape == (len(agents), dim) and np.all(np.isfinite(v)))
        for r in range(len(agents)):
            _check_rotation(grp, grp.take(rows.rot, [r]))

    _accepted_or_counted(
        wire.decode_block(msg, grp, dim, RUN_ID, BLOCK, K, wire.ROTATION_TOL, T_MAX), counter,
        check,
    )


def test_a_block_round_trips_every_row_bit_for_bit():
    """encode_block -> decode_block gives each agent's values exactly (what a per-agent
    message of the same row gives), so packed lockstep computes with the same numbers."""
    from std_msgs.msg import Float64MultiArray

    from polymatch_ros.ros import wire

    rng = np.random.default_rng(3)
    for dim, angle in ((2, True), (2, False), (3, False), (4, False)):
        grp = _group(dim, angle)
        n = 3
        mats = np.linalg.qr(rng.normal(size=(n, dim, dim)))[0]
        mats[np.linalg.det(mats) < 0, :, 0] *= -1
        rot = grp.from_matrices(mats)
        values = rot[:, None] if grp.name == "angle" else grp.to_matrices(rot).reshape(n, -1)
        x, v = rng.normal(size=(n, dim)), rng.normal(size=(n, dim))
        agents = [9, 10, 11]
        msg = wire.encode_block(Float64MultiArray(), RUN_ID, BLOCK, 5, 2, 1, 0.75, agents,
                                {"x": x, "v": v, "rot": values})
        rows, reason = wire.decode_block(msg, grp, dim, RUN_ID, BLOCK, K,
                                         wire.ROTATION_TOL, T_MAX)
        assert reason is None, reason
        assert (rows.step, rows.stage, rows.flags, rows.t) == (5, 2, 1, 0.75)
        assert rows.agents.tolist() == agents
        for r in range(n):
            assert np.array_equal(rows.x[r], x[r]) and np.array_equal(rows.v[r], v[r])
            one = wire.rot_from_values(grp, wire.rot_values(grp, grp.take(rot, [r])))
            assert np.array_equal(grp.take(rows.rot, [r]), one)
        _, reason = wire.decode_block(msg, grp, dim, RUN_ID, BLOCK + 1, K)
        assert reason == "unknown sender (agent index)"
        _, reason = wire.decode_block(msg, grp, dim, RUN_ID, BLOCK, 2)
        assert reason == "unknown sender (agent index)"


def test_a_valid_message_of_each_kind_is_accepted():
    """The decoders are not simply refusing everything: an agent's own messages pass."""
    from std_msgs.msg import Float64MultiArray

    from polymatch_ros.ros import wire

    for dim in (2, 3, 4):
        grp = _matrix_group(dim)
        rot = grp.from_matrices(np.eye(dim)[None])
        x = np.arange(dim, dtype=float)
        got, reason = wire.decode_pose_msg(
            wire.pose_message(grp, 1.5, x, rot, "world"), grp, dim, "world", T_MAX
        )
        assert reason is None and got.t == 1.5 and np.allclose(got.vec, x)
        w = grp.algebra_take(grp.algebra_zeros(1), [0])
        got, reason = wire.decode_twist_msg(
            wire.twist_message(grp, 1.5, x, w, "world"), grp, dim, "world", T_MAX
        )
        assert reason is None and np.allclose(got.vec, x)
        msg = wire.encode_stage(
            Float64MultiArray(),
            RUN_ID,
            3,
            4,
            1,
            0,
            1.25,
            {"x": x.tolist(), "rot": wire.rot_values(grp, rot)},
        )
        stage, reason = wire.decode_stage(msg, grp, dim, RUN_ID, 3, wire.ROTATION_TOL, T_MAX)
        assert reason is None and (stage.step, stage.stage, stage.t) == (4, 1, 1.25)


def test_a_flood_of_drops_is_counted_in_full_and_warned_once_a_second_per_reason():
    """Every dropped message is counted; the warnings are throttled before the logger is
    called (a flood must not cost a logger call per message)."""
    from polymatch_ros.ros.nodes.exchange import DropCounter

    class Logger:
        def __init__(self):
            self.lines = []

        def warning(self, text):
            self.lines.append(text)

    logger = Logger()
    drops = DropCounter(logger)
    for k in range(1000):
        drops("agent 3", "non-finite value" if k % 2 else "unknown sender (run id)")
    assert drops.counts == {"non-finite value": 500, "unknown sender (run id)": 500}
    assert drops.total == 1000
    assert len(logger.lines) == 2, logger.lines
    assert "non-finite value (1 so far)" in logger.lines[1]
    drops._warned = {reason: t - DropCounter.LOG_PERIOD for reason, t in drops._warned.items()}
    drops("agent 3", "non-finite value")
    assert len(logger.lines) == 3 and "(501 so far)" in logger.lines[2]
