"""Never poisoned from the wire: every decoder of the run's messages either accepts a message -
and then its values are the message's own, finite, within 1e100, stamped inside the run, of
this run and sender, its rotations in SO(d) (Lemma 2.1: the flow keeps O_i orthogonal, det +1)
- or drops it with a non-empty reason.  It never raises.  Messages are built directly (no DDS).

Each fuzzer first runs explicit examples (``@example``), each with its expected outcome
(``ACCEPTED``, or the exact reason) asserted: valid messages of each shape, and one message per
way it is dropped; random draws follow, from a valid message whose typed fields are each kept
or replaced (any float, NaN, infinities, 1e308, subnormals, wrong lengths, other ids, stamps).
SO(d) is checked here with numpy (|R^T R - I| < 1e-8, det > 0); rotations are drawn here (QR of
a Gaussian matrix).  test_wire_rejections.py asserts every reason on hand-made messages.
"""

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from ros_harness import needs_ros

pytestmark = needs_ros

# 50 random messages per fuzzer (a new draw each run), after its explicit examples: those reach
# every outcome, acceptance included.
SETTINGS = settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.too_slow])
T_MAX, SLACK, BOUND = 30.0, 1e-6, 1e100
RUN_ID, AGENT = 77, 3
BLOCK, K = 2, 4  # block 2 of 4 agents: agents 8 .. 11
NAN, INF = math.nan, math.inf
ACCEPTED = "accepted"
REFUSED = "refused"  # the run record and the command: refused (None), no reason given

floats = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True, width=64),
    st.sampled_from([0.0, -0.0, 5e-324, -5e-324, 1e-310, 1e308, -1e308, 1.0, -1.0, 0.5, NAN,
                     INF, -INF, 1e100, 1e101, 0.7071067811865476]),
)
stamps = st.tuples(
    st.integers(-2**31, 2**31 - 1) | st.sampled_from([-1, 0, 1, 29, 30, 31, 10**9]),
    st.integers(0, 2**32 - 1) | st.sampled_from([0, 999_999_999, 10**9]),
)


def _group(dim, angle=False):
    """The core's rotation representations: an angle (d = 2), SO(3), a d x d matrix."""
    from polymatch_ros.core.so import SO2, SO3, SOn

    if angle and dim == 2:
        return SO2()
    return SO3() if dim == 3 else SOn(dim)


def _rotation(dim, seed):
    """A rotation in SO(dim) from ``seed``: Q of a Gaussian matrix's QR, its columns' signs set
    by R's diagonal (Haar, as scipy's special_ortho_group draws), one flipped if det < 0."""
    q, r = np.linalg.qr(np.random.default_rng(seed).normal(size=(dim, dim)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


def _flat(*mats):
    return [float(v) for m in mats for v in np.asarray(m).ravel()]


def _in_so_d(mat):
    mat = np.asarray(mat)
    assert np.all(np.isfinite(mat))
    assert np.max(np.abs(mat.T @ mat - np.eye(len(mat)))) < 1e-8 and np.linalg.det(mat) > 0


def _bounded(values):
    values = np.asarray(values, dtype=float)
    assert np.all(np.isfinite(values)) and np.all(np.abs(values) <= BOUND)


def _time_of(stamp):
    t = stamp[0] + 1e-9 * stamp[1]
    assert stamp[1] < 10**9 and 0.0 <= t <= T_MAX + SLACK
    return t


def _judge(result, expected, check):
    """An explicit example's outcome is its expected one; any outcome is an accepted message
    whose values pass ``check``, or a drop with a non-empty reason."""
    value, reason = result
    if expected is not None:
        assert (reason is None) if expected == ACCEPTED else (value, reason) == (None, expected)
    if value is None:
        assert isinstance(reason, str) and reason
    else:
        assert reason is None
        check(value)


def _with_examples(cases):
    """Decorate a fuzzer with the explicit examples ``cases`` (``case`` and ``expected``)."""
    def decorate(test):
        for case in reversed(cases):
            test = example(**case)(test)
        return test
    return decorate


def _kept(draw, valid, fuzz):
    """A field: its valid value (two draws in three) or ``fuzz``'s."""
    return valid if draw(st.integers(0, 2)) else draw(fuzz)


def _vector(draw, valid):
    """A float64[] field: kept, one entry any float, or any list of floats."""
    how = draw(st.sampled_from(["keep", "keep", "keep", "entry", "list"]))
    if how == "entry" and valid:
        valid = list(valid)
        valid[draw(st.integers(0, len(valid) - 1))] = draw(floats)
    elif how == "list":
        valid = draw(st.lists(floats, max_size=len(valid) + 2))
    return valid


def _ids(draw, valid, width):
    return _kept(draw, valid, st.sampled_from([valid + 1, 0, 2**width - 1])
                 | st.integers(0, 2**width - 1))


# -- an agent's state (AgentState) -------------------------------------------------------------


def _state_values(dim, seed, second):
    """A valid state of agent 3: centroid, rotation, and in second order v and a skew W."""
    rng = np.random.default_rng(seed)
    rot, spin = _rotation(dim, seed), rng.normal(size=(dim, dim))
    return {"centroid": rng.normal(size=dim).tolist(), "rotation": _flat(rot),
            "velocity": rng.normal(size=dim).tolist() if second else [],
            "angular_velocity": _flat(spin - spin.T) if second else []}


@st.composite
def state_cases(draw):
    dim, angle = draw(st.sampled_from([(2, True), (2, False), (3, False), (4, False)]))
    case = {"dim": dim, "angle": angle, "run_id": _ids(draw, RUN_ID, 64),
            "agent": _ids(draw, AGENT, 32), "stamp": _kept(draw, (1, 250_000_000), stamps)}
    valid = _state_values(dim, draw(st.integers(0, 2**16)), draw(st.booleans()))
    return case | {label: _vector(draw, values) for label, values in valid.items()}


def _state_case(dim=3, angle=False, second=True, stamp=(1, 250_000_000), **changes):
    case = {"dim": dim, "angle": angle, "run_id": RUN_ID, "agent": AGENT, "stamp": stamp,
            **_state_values(dim, 5, second)}
    return case | changes


ROT3 = _flat(_rotation(3, 5))
STATE_CASES = [(case, expected) for case, expected in [
    (_state_case(), ACCEPTED), (_state_case(2, True, False), ACCEPTED),
    (_state_case(4, stamp=(30, 999)), ACCEPTED), (_state_case(centroid=[1e100, 0.0, -5e-324]),
                                                  ACCEPTED),
    (_state_case(run_id=RUN_ID + 1), "unknown sender (run id)"),
    (_state_case(agent=0), "unknown sender (agent index)"),
    (_state_case(stamp=(1, 10**9)), "malformed header"),
    (_state_case(stamp=(-1, 999_999_999)), "stamp outside the run"),
    (_state_case(velocity=[]), "malformed layout"),
    (_state_case(rotation=ROT3[:8]), "malformed layout"),
    (_state_case(centroid=[NAN, 0.0, 0.0]), "non-finite value"),
    (_state_case(centroid=[1e101, 0.0, 0.0]), "value out of range"),
    (_state_case(rotation=_flat(-np.reshape(ROT3, (3, 3)))), "rotation not in SO(d)"),
    (_state_case(angular_velocity=_flat(np.eye(3))), "angular velocity not skew"),
    # skew to round-off (a subnormal on the diagonal) is taken, and kept exactly skew
    (_state_case(2, angular_velocity=[1.2651982965703258e-293, -0.772527513734584,
                                      0.772527513734584, 0.0]), ACCEPTED),
    (_state_case(4, angular_velocity=_flat(np.diag([5e-324, 0.0, 0.0, 0.0])
                                           + np.triu(np.ones((4, 4)), 1)
                                           - np.tril(np.ones((4, 4)), -1))), ACCEPTED),
]]
STATE_EXAMPLES = [{"case": c, "expected": e} for c, e in STATE_CASES]


def _state_outcome(case, expected):
    from polymatch_interfaces.msg import AgentState
    from polymatch_ros.ros import wire

    dim, grp = case["dim"], _group(case["dim"], case["angle"])
    msg = AgentState(run_id=case["run_id"], agent=case["agent"], centroid=case["centroid"],
                     rotation=case["rotation"], velocity=case["velocity"],
                     angular_velocity=case["angular_velocity"])
    msg.header.stamp.sec, msg.header.stamp.nanosec = case["stamp"]

    def check(got):
        assert (case["run_id"], case["agent"]) == (RUN_ID, AGENT)
        assert got.t == _time_of(case["stamp"])
        _check_state(grp, dim, got, case["centroid"], case["rotation"], case["velocity"],
                     case["angular_velocity"])

    _judge(wire.decode_exchange(msg, grp, dim, RUN_ID, AGENT, T_MAX), expected, check)


def _check_state(grp, dim, got, centroid, rotation, velocity, spin):
    """An accepted state holds the message's numbers: bounded, its rotation in SO(d) (the
    sent matrix, or in 2-D angles its cos/sin to round-off), W skew."""
    _bounded(got.x)
    assert got.x.tolist() == list(centroid)
    mat = grp.to_matrices(got.rot)[0]
    _in_so_d(mat)
    assert np.max(np.abs(mat - np.reshape(rotation, (dim, dim)))) <= 1e-8
    if grp.name != "angle":
        assert mat.ravel().tolist() == list(rotation)
    if got.v is None:
        assert not len(velocity) and not len(spin)
        return
    _bounded(got.v)
    assert got.v.tolist() == list(velocity)
    skew = grp.algebra_to_skew(got.w)[0]
    _bounded(skew)
    assert np.array_equal(skew, -skew.T)
    assert np.max(np.abs(skew - np.reshape(spin, (dim, dim)))) <= 1e-9 * max(1.0, np.max(
        np.abs(spin)))


@SETTINGS
@given(case=state_cases(), expected=st.none())
@_with_examples(STATE_EXAMPLES)
def test_agent_state_is_accepted_valid_or_dropped_lemma_2_1(case, expected):
    _state_outcome(case, expected)


# -- a block of states (AgentStateBlock) -------------------------------------------------------


PLURAL = {"centroid": "centroids", "rotation": "rotations", "velocity": "velocities",
          "angular_velocity": "angular_velocities"}   # AgentState's fields -> the block's


@st.composite
def state_block_cases(draw):
    dim, angle = draw(st.sampled_from([(2, True), (2, False), (3, False), (4, False)]))
    members = draw(st.permutations(range(BLOCK * K, BLOCK * K + K)))
    agents = list(members[:draw(st.integers(1, K))])
    second, seed = draw(st.booleans()), draw(st.integers(0, 2**16))
    rows = [_state_values(dim, seed + a, second) for a in agents]
    case = {"dim": dim, "angle": angle, "run_id": _ids(draw, RUN_ID, 64),
            "block": _ids(draw, BLOCK, 32), "stamp": _kept(draw, (1, 250_000_000), stamps),
            "agents": _kept(draw, agents, st.lists(st.sampled_from(
                [7, 8, 9, 10, 11, 12, 0, 2**32 - 1]), max_size=K + 1))}
    return case | {PLURAL[label]: _vector(draw, [v for row in rows for v in row[label]])
                   for label in rows[0]}


def _state_block_case(dim=3, agents=(8, 9), second=True, **changes):
    rows = [_state_values(dim, a, second) for a in agents]
    return {"dim": dim, "angle": False, "run_id": RUN_ID, "block": BLOCK,
            "stamp": (1, 250_000_000), "agents": list(agents),
            **{PLURAL[label]: [v for row in rows for v in row[label]] for label in PLURAL}
            } | changes


STATE_BLOCK_EXAMPLES = [{"case": c, "expected": e} for c, e in [
    (_state_block_case(), ACCEPTED), (_state_block_case(2, (11, 8, 10), False), ACCEPTED),
    (_state_block_case(4, (10,)), ACCEPTED),
    (_state_block_case(run_id=0), "unknown sender (run id)"),
    (_state_block_case(agents=[8, 8]), "unknown sender (agent index)"),
    (_state_block_case(agents=[9, 12]), "unknown sender (agent index)"),
    (_state_block_case(block=BLOCK + 1), "unknown sender (agent index)"),
    (_state_block_case() | {"agents": []}, "malformed layout"),
    (_state_block_case(stamp=(31, 0)), "stamp outside the run"),
    (_state_block_case(centroids=[0.0] * 5 + [INF]), "non-finite value"),
    (_state_block_case(rotations=ROT3 + _flat(np.diag([1.0, -1.0, 1.0]))),
     "rotation not in SO(d)"),
]]


def _state_block_outcome(case, expected):
    from polymatch_interfaces.msg import AgentStateBlock
    from polymatch_ros.ros import wire

    dim, grp = case["dim"], _group(case["dim"], case["angle"])
    fields = ("run_id", "block", "agents", "centroids", "rotations", "velocities",
              "angular_velocities")
    msg = AgentStateBlock(**{f: case[f] for f in fields})
    msg.header.stamp.sec, msg.header.stamp.nanosec = case["stamp"]

    def check(rows):
        agents = [a for a, _ in rows]
        assert (case["run_id"], case["block"], agents) == (RUN_ID, BLOCK, case["agents"])
        assert 1 <= len(agents) <= K and len(set(agents)) == len(agents)
        assert all(BLOCK * K <= a < (BLOCK + 1) * K for a in agents)
        second = bool(len(case["velocities"]))
        for r, (_, got) in enumerate(rows):
            assert got.t == _time_of(case["stamp"])
            part = {label: case[label][r * width:(r + 1) * width] for label, width in (
                ("centroids", dim), ("rotations", dim * dim), ("velocities", dim * second),
                ("angular_velocities", dim * dim * second))}
            _check_state(grp, dim, got, *part.values())

    _judge(wire.decode_exchange_block(msg, grp, dim, RUN_ID, BLOCK, K, T_MAX), expected, check)


@SETTINGS
@given(case=state_block_cases(), expected=st.none())
@_with_examples(STATE_BLOCK_EXAMPLES)
def test_state_block_is_accepted_valid_or_dropped_whole_lemma_2_1(case, expected):
    _state_block_outcome(case, expected)


# -- lockstep stage rows, of one agent and of a block (StageRows) ------------------------------


def _stage_values(dim, angle, seed, n, parts):
    """Valid rows of n agents: centroids and velocities where ``parts`` has them, rotations as
    angles (2-D angle integrators) or matrices in SO(d)."""
    rng = np.random.default_rng(seed)
    rot = rng.uniform(-4.0, 4.0, n).tolist() if angle else _flat(
        *[_rotation(dim, seed + r) for r in range(n)])
    return {"centroids": rng.normal(size=n * dim).tolist() if "x" in parts else [],
            "velocities": rng.normal(size=n * dim).tolist() if "v" in parts else [],
            "rotations": rot}


@st.composite
def stage_cases(draw, block):
    dim, angle = draw(st.sampled_from([(2, True), (2, False), (3, False), (4, False)]))
    if block:
        members = draw(st.permutations(range(BLOCK * K, BLOCK * K + K)))
        agents = list(members[:draw(st.integers(1, K))])
        wrong = st.lists(st.sampled_from([7, 8, 9, 11, 12, 0]), max_size=K + 1)
    else:
        agents, wrong = [AGENT], st.lists(st.sampled_from([AGENT, AGENT + 1, 0]), max_size=2)
    parts = draw(st.sampled_from(["", "x", "v", "xv"]))
    case = {"dim": dim, "angle": angle, "run_id": _ids(draw, RUN_ID, 64),
            "sender": _ids(draw, BLOCK if block else AGENT, 32),
            "step": draw(st.integers(0, 2**64 - 1) | st.just(4)),
            "stage": draw(st.integers(0, 2**32 - 1) | st.just(1)),
            "stop": draw(st.booleans()), "stop_step": draw(st.integers(-1, 2**62)),
            "t": _kept(draw, 1.25, floats | st.sampled_from([T_MAX, T_MAX + 2 * SLACK])),
            "agents": _kept(draw, agents, wrong)}
    valid = _stage_values(dim, angle, draw(st.integers(0, 2**16)), len(agents), parts)
    return case | {label: _vector(draw, values) for label, values in valid.items()}


def _stage_case(dim=3, angle=False, agents=(AGENT,), parts="x", sender=AGENT, **changes):
    return {"dim": dim, "angle": angle, "run_id": RUN_ID, "sender": sender, "step": 4,
            "stage": 1, "stop": False, "stop_step": -1, "t": 1.25, "agents": list(agents),
            **_stage_values(dim, angle, 5, len(agents), parts)} | changes


def _block_case(dim=3, angle=False, agents=(8, 9), parts="x", **changes):
    return _stage_case(dim, angle, agents, parts, BLOCK) | changes


TILTED = _flat(1.001 * np.eye(3))
REFLECTION = _flat(np.diag([-1.0, 1.0, 1.0]))
STAGE_EXAMPLES = [{"case": c, "expected": e} for c, e in [
    (_stage_case(), ACCEPTED), (_stage_case(2, True, parts="xv"), ACCEPTED),
    (_stage_case(4, parts="", t=T_MAX + 0.5 * SLACK, stop=True, stop_step=9), ACCEPTED),
    (_stage_case(run_id=RUN_ID + 1), "unknown sender (run id)"),
    (_stage_case(sender=AGENT + 1), "unknown sender (agent index)"),
    (_stage_case(agents=[]), "malformed layout"),
    (_stage_case(t=NAN), "stamp outside the run"),
    (_stage_case(centroids=[NAN, 0.0, 0.0]), "non-finite value"),
    (_stage_case(velocities=[0.0, 1e101]), "malformed layout"),     # a velocity of 2 entries
    (_stage_case(parts="xv", velocities=[0.0, 0.0, 1e101]), "value out of range"),
    (_stage_case(rotations=TILTED), "rotation not orthogonal"),
    (_stage_case(rotations=REFLECTION), "rotation not in SO(d)"),
]]
BLOCK_EXAMPLES = [{"case": c, "expected": e} for c, e in [
    (_block_case(), ACCEPTED), (_block_case(2, True, (11, 8, 10), "v"), ACCEPTED),
    (_block_case(4, agents=(9,), parts=""), ACCEPTED),
    (_block_case(run_id=0), "unknown sender (run id)"),
    (_block_case(sender=AGENT), "unknown sender (agent index)"),
    (_block_case(agents=[7, 8]), "unknown sender (agent index)"),
    (_block_case(agents=[9, 9]), "unknown sender (agent index)"),
    (_block_case(t=-0.5), "stamp outside the run"),
    (_block_case(centroids=[0.0] * 5), "malformed layout"),
    (_block_case(centroids=[0.0] * 5 + [-INF]), "non-finite value"),
    (_block_case(rotations=ROT3 + TILTED), "rotation not orthogonal"),
    (_block_case(rotations=ROT3 + REFLECTION), "rotation not in SO(d)"),
]]


def _stage_outcome(case, expected, block):
    from polymatch_interfaces.msg import StageRows
    from polymatch_ros.ros import wire

    dim, grp = case["dim"], _group(case["dim"], case["angle"])
    msg = StageRows(**{f: case[f] for f in case if f not in ("dim", "angle")})
    if block:
        result = wire.decode_block(msg, grp, dim, RUN_ID, BLOCK, K, wire.ROTATION_TOL, T_MAX)
    else:
        result = wire.decode_stage(msg, grp, dim, RUN_ID, AGENT, wire.ROTATION_TOL, T_MAX)
        if result[0] is not None:     # one agent's row, as a block of one
            stage = result[0]
            assert stage.agent == AGENT
            result = (wire.StageRows.of(stage), None)

    def check(rows):
        assert (case["run_id"], case["sender"]) == (RUN_ID, BLOCK if block else AGENT)
        agents = rows.agents.tolist()
        assert agents == case["agents"] and len(set(agents)) == len(agents)
        assert all(BLOCK * K <= a < (BLOCK + 1) * K for a in agents) if block else \
            agents == [AGENT]
        assert (rows.step, rows.stage, rows.t) == (case["step"], case["stage"], case["t"])
        assert 0.0 <= rows.t <= T_MAX + SLACK
        assert rows.flags == (case["stop"] | (max(case["stop_step"], 0) << 1) * case["stop"])
        for got, label in ((rows.x, "centroids"), (rows.v, "velocities")):
            assert (got is None) == (not len(case[label]))
            if got is not None:
                _bounded(got)
                assert got.ravel().tolist() == case[label]
        if grp.name == "angle":
            _bounded(rows.rot)
            assert rows.rot.tolist() == case["rotations"]
        else:
            mats = grp.to_matrices(rows.rot)
            for m in mats:
                _in_so_d(m)
            assert mats.ravel().tolist() == case["rotations"]

    _judge(result, expected, check)


@SETTINGS
@given(case=stage_cases(block=False), expected=st.none())
@_with_examples(STAGE_EXAMPLES)
def test_stage_rows_are_accepted_valid_or_dropped_lemma_2_1(case, expected):
    _stage_outcome(case, expected, block=False)


@SETTINGS
@given(case=stage_cases(block=True), expected=st.none())
@_with_examples(BLOCK_EXAMPLES)
def test_block_stage_rows_are_accepted_valid_or_dropped_whole_lemma_2_1(case, expected):
    """A packed process's rows: every row valid, in the block and once, or the whole message
    dropped with a reason."""
    _stage_outcome(case, expected, block=True)


# -- poses and velocities, d <= 3 (PoseStamped, TwistStamped) ----------------------------------

frames = st.sampled_from(["world", "world", "map", "", "World"])
QUAT = (0.0, 0.0, math.sin(0.2), math.cos(0.2))   # a turn of 0.4 rad about z: planar


def _quaternion_matrix(q):
    """The rotation of a quaternion (x, y, z, w), normalised: the textbook formula."""
    x, y, z, w = np.asarray(q) / math.sqrt(sum(v * v for v in q))
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def _hat(ang, dim):
    x, y, z = ang
    full = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return full if dim == 3 else np.array([[0.0, -z], [z, 0.0]])


def _geometry_outcome(kind, dim, vector, rotation, stamp, frame, expected):
    from geometry_msgs.msg import PoseStamped, TwistStamped

    from polymatch_ros.ros import wire

    grp = _group(dim)
    msg = PoseStamped() if kind == "pose" else TwistStamped()
    body = msg.pose if kind == "pose" else msg.twist
    first, second = (body.position, body.orientation) if kind == "pose" else (body.linear,
                                                                              body.angular)
    first.x, first.y, first.z = vector
    for axis, value in zip("xyzw", rotation):
        setattr(second, axis, value)
    msg.header.frame_id = frame
    msg.header.stamp.sec, msg.header.stamp.nanosec = stamp

    def check(got):
        assert frame == "world" and got.t == _time_of(stamp)
        _bounded(got.vec)
        assert got.vec.tolist() == list(vector[:dim])
        if kind == "pose":
            mat = grp.to_matrices(got.rot)[0]
            _in_so_d(mat)
            assert np.max(np.abs(mat - _quaternion_matrix(rotation)[:dim, :dim])) < 1e-8
        else:
            skew = grp.algebra_to_skew(got.rot)[0]
            _bounded(skew)
            assert np.array_equal(skew, _hat(rotation, dim))

    decode = wire.decode_pose_msg if kind == "pose" else wire.decode_twist_msg
    _judge(decode(msg, grp, dim, "world", T_MAX), expected, check)


def _geometry_examples(vector, rotation, valid, off_plane, planar_reason):
    """Explicit examples of a pose or twist fuzzer: ``vector`` and ``rotation`` name its two
    parts, ``valid`` their valid values; accepted in 3-D and 2-D, then one of each outcome."""
    def case(expected, dim=3, stamp=(1, 0), frame="world", **parts):
        return {"dim": dim, vector: valid[0], rotation: valid[1], "stamp": stamp,
                "frame": frame, "expected": expected, **parts}

    return [case(ACCEPTED), case(ACCEPTED, dim=2, stamp=(29, 999_999_999)),
            case(ACCEPTED, **{vector: (1e100, -5e-324, 0.0)}),
            case("non-finite value", **{vector: (NAN, 0.0, 0.0)}),
            case("non-finite value", **{rotation: valid[1][:-1] + (INF,)}),
            case("value out of range", **{vector: (0.0, 1e101, 0.0)}),
            case(planar_reason, dim=2, **{vector: (0.0, 0.0, 0.5)}),
            case(planar_reason, dim=2, **{rotation: off_plane}),
            case("unknown frame 'map'", frame="map"), case("unknown frame ''", frame=""),
            case("unknown frame 'World'", frame="World"),
            case("malformed header", stamp=(1, 10**9)),
            case("stamp outside the run", stamp=(31, 0)),
            case("stamp outside the run", stamp=(-1, 0))]


POSE_EXAMPLES = _geometry_examples("pos", "quat", ((0.5, -1.0, 0.0), QUAT),
                                   (0.6, 0.0, 0.0, 0.8), "not a planar pose")
POSE_EXAMPLES += [POSE_EXAMPLES[0] | {"quat": (0.0, 0.0, 0.0, 1.001),
                                      "expected": "quaternion far from unit norm"},
                  POSE_EXAMPLES[0] | {"quat": (0.5, -0.5, 0.5, 0.5), "expected": ACCEPTED}]


@SETTINGS
@given(
    dim=st.sampled_from([2, 3]),
    pos=st.tuples(floats, floats, floats),
    quat=st.one_of(st.tuples(floats, floats, floats, floats),
                   st.tuples(*[st.floats(-1, 1)] * 4),
                   st.integers(0, 2**16).map(lambda s: tuple(np.random.default_rng(s).normal(
                       size=4) / 1.0)).map(lambda q: tuple(np.array(q) / np.linalg.norm(q)))),
    stamp=stamps,
    frame=frames,
    expected=st.none(),
)
@_with_examples(POSE_EXAMPLES)
def test_pose_stamped_is_accepted_valid_or_dropped_lemma_2_1(dim, pos, quat, stamp, frame,
                                                             expected):
    _geometry_outcome("pose", dim, pos, quat, stamp, frame, expected)


TWIST_EXAMPLES = _geometry_examples("lin", "ang", ((0.5, -1.0, 0.0), (0.0, 0.0, 0.3)),
                                    (1.0, 0.0, 0.3), "not a planar velocity")


@SETTINGS
@given(
    dim=st.sampled_from([2, 3]),
    lin=st.tuples(floats, floats, floats),
    ang=st.tuples(floats, floats, floats),
    stamp=stamps,
    frame=frames,
    expected=st.none(),
)
@_with_examples(TWIST_EXAMPLES)
def test_twist_stamped_is_accepted_valid_or_dropped(dim, lin, ang, stamp, frame, expected):
    _geometry_outcome("twist", dim, lin, ang, stamp, frame, expected)


# -- poses and velocities, d >= 4 (PoseNd, TwistNd) --------------------------------------------


@st.composite
def nd_cases(draw):
    dim, kind = draw(st.sampled_from([4, 5])), draw(st.sampled_from(["pose", "twist"]))
    mat = _rotation(dim, draw(st.integers(0, 2**16)))
    return {"dim": dim, "kind": kind, "stamp": _kept(draw, (1, 0), stamps),
            "frame": _kept(draw, "world", frames),
            "vec": _vector(draw, np.arange(dim, dtype=float).tolist()),
            "mat": _vector(draw, _flat(mat if kind == "pose" else mat - mat.T))}


def _nd_case(expected, dim=4, kind="pose", stamp=(1, 0), frame="world", **changes):
    mat = _rotation(dim, 7)
    case = {"dim": dim, "kind": kind, "stamp": stamp, "frame": frame,
            "vec": [0.5, -1.0, 2.0, 0.0, 3.0][:dim],
            "mat": _flat(mat if kind == "pose" else mat - mat.T)}
    return {"case": case | changes, "expected": expected}


ND_EXAMPLES = [
    _nd_case(ACCEPTED), _nd_case(ACCEPTED, 5, "twist", (30, 999)),
    _nd_case("unknown frame 'map'", frame="map"), _nd_case("malformed header", stamp=(0, 10**9)),
    _nd_case("stamp outside the run", kind="twist", stamp=(31, 0)),
    _nd_case("malformed layout", vec=[0.5]), _nd_case("non-finite value", vec=[NAN] * 4),
    _nd_case("value out of range", vec=[0.0, 0.0, 0.0, -1e101]),
    _nd_case("rotation not in SO(d)", mat=[0.0] * 16),                 # a zero matrix
    _nd_case("rotation not in SO(d)", mat=_flat(-_rotation(5, 7)), dim=5),   # det -1
    _nd_case("angular velocity not skew", kind="twist", mat=_flat(np.eye(4))),
    # skew to round-off (a subnormal on the diagonal): taken, and kept exactly skew
    _nd_case(ACCEPTED, kind="twist", mat=_flat(_rotation(4, 7) - _rotation(4, 7).T
                                              + np.diag([2.3e-242, 0.0, 0.0, 0.0]))),
]


def _nd_outcome(case, expected):
    from polymatch_interfaces.msg import PoseNd, TwistNd
    from polymatch_ros.ros import wire

    dim, pose = case["dim"], case["kind"] == "pose"
    grp = _group(dim)
    msg = PoseNd(position=case["vec"], orientation=case["mat"]) if pose else \
        TwistNd(linear=case["vec"], angular=case["mat"])
    msg.header.frame_id = case["frame"]
    msg.header.stamp.sec, msg.header.stamp.nanosec = case["stamp"]

    def check(got):
        assert case["frame"] == "world" and got.t == _time_of(case["stamp"])
        _bounded(got.vec)
        assert got.vec.tolist() == case["vec"]
        mat = grp.to_matrices(got.rot)[0] if pose else grp.algebra_to_skew(got.rot)[0]
        _bounded(mat)
        sent = np.reshape(case["mat"], (dim, dim))
        if pose:
            assert mat.ravel().tolist() == case["mat"]
            _in_so_d(mat)
            return
        # in so(d) exactly; the sent W itself when it is skew, else within the skew tolerance
        assert np.array_equal(mat, -mat.T)
        if np.array_equal(sent, -sent.T):
            assert mat.ravel().tolist() == case["mat"]
        else:
            scale = max(1.0, float(np.max(np.abs(sent))))
            assert np.max(np.abs(mat - sent)) <= wire.ROTATION_TOL * scale

    decode = wire.decode_pose_msg if pose else wire.decode_twist_msg
    _judge(decode(msg, grp, dim, "world", T_MAX), expected, check)


@SETTINGS
@given(case=nd_cases(), expected=st.none())
@_with_examples(ND_EXAMPLES)
def test_pose_and_twist_nd_are_accepted_valid_or_dropped_lemma_2_1(case, expected):
    _nd_outcome(case, expected)


# -- the run record and the control command -----------------------------------------------------


@st.composite
def record_cases(draw):
    return {"role": draw(st.sampled_from(["agent", "monitor", "robot", ""]) | st.text()),
            "t": draw(floats), "matched_after": draw(floats),
            "offset": draw(st.sampled_from(["1", "12", "x", "", "-3"])), "value": draw(floats)}


def _record_case(expected, **changes):
    case = {"role": "agent", "t": 2.5, "matched_after": NAN, "offset": "1", "value": -0.004}
    return {"case": case | changes, "expected": expected}


RECORD_EXAMPLES = [_record_case(ACCEPTED), _record_case(ACCEPTED, role="monitor",
                                                        matched_after=3.5, offset="12"),
                   _record_case(REFUSED, role="robot"), _record_case(REFUSED, t=NAN),
                   _record_case(REFUSED, t=-INF), _record_case(REFUSED, offset="x")]


def _record_outcome(case, expected):
    from polymatch_interfaces.msg import NamedValue, RunRecord
    from polymatch_ros.ros import wire

    msg = RunRecord(role=case["role"], mode="realtime", t=case["t"],
                    matched_after=case["matched_after"],
                    clock_offsets=[NamedValue(name=case["offset"], value=case["value"])])
    try:
        rec = wire.RunRecord.from_msg(msg)
    except Exception as error:            # noqa: BLE001 - the claim: it never raises
        pytest.fail(f"from_msg raised {error!r}")
    if expected is not None:
        assert (rec is not None) == (expected == ACCEPTED)
    if rec is not None:
        assert rec.role in ("agent", "monitor") and rec.role == case["role"]
        assert math.isfinite(rec.t) and rec.t == case["t"]
        assert rec.matched_after is None if math.isnan(case["matched_after"]) else \
            rec.matched_after == case["matched_after"]
        assert list(rec.clock_offsets) == [int(case["offset"])]


@SETTINGS
@given(case=record_cases(), expected=st.none())
@_with_examples(RECORD_EXAMPLES)
def test_run_record_is_read_or_refused_never_raises(case, expected):
    _record_outcome(case, expected)


VERBS = ("START", "STOP", "PAUSE", "RESUME", "RESET", "RECEIVED")   # the .msg file's constants


def _command_outcome(case, expected):
    from builtin_interfaces.msg import Time

    from polymatch_interfaces.msg import ControlCommand
    from polymatch_ros.ros.wire import control

    sec, nanosec = case["epoch"]
    got = control.parse_command(ControlCommand(command=case["command"],
                                               epoch=Time(sec=sec, nanosec=nanosec)))
    if expected is not None:
        assert (got is not None) == (expected == ACCEPTED)
    if got is not None:
        constant = VERBS[case["command"]]
        assert case["command"] == getattr(ControlCommand, constant) and nanosec < 10**9
        if constant in ("STOP", "RECEIVED"):
            assert got == (constant.lower(), None)
        else:
            assert got == (constant.lower(), sec + 1e-9 * nanosec) and got[1] > 0


COMMAND_EXAMPLES = [{"case": {"command": c, "epoch": e}, "expected": x} for c, e, x in [
    (0, (1000, 250_000_000), ACCEPTED), (1, (0, 0), ACCEPTED), (5, (-7, 3), ACCEPTED),
    (6, (1000, 0), REFUSED), (2, (0, 0), REFUSED), (4, (-5, 0), REFUSED),
    (0, (1000, 10**9), REFUSED)]]


@SETTINGS
@given(case=st.fixed_dictionaries({"command": st.integers(0, 255) | st.integers(0, 6),
                                   "epoch": stamps}), expected=st.none())
@_with_examples(COMMAND_EXAMPLES)
def test_control_command_is_read_or_refused(case, expected):
    _command_outcome(case, expected)


# -- a decoder that drops everything fails the fuzzers -----------------------------------------

FUZZERS = {  # name: (its explicit examples, how one is judged, the decoder it calls)
    "state": (STATE_EXAMPLES, _state_outcome, "decode_exchange"),
    "state block": (STATE_BLOCK_EXAMPLES, _state_block_outcome, "decode_exchange_block"),
    "stage": (STAGE_EXAMPLES, lambda case, expected: _stage_outcome(case, expected, False),
              "decode_stage"),
    "block": (BLOCK_EXAMPLES, lambda case, expected: _stage_outcome(case, expected, True),
              "decode_block"),
    "nd": (ND_EXAMPLES, _nd_outcome, "decode_pose_msg decode_twist_msg"),
}


@pytest.mark.parametrize("name", list(FUZZERS))
def test_a_decoder_that_drops_everything_fails_its_fuzzer(name, monkeypatch):
    """Every fuzzer's explicit examples include accepted messages: with the decoder replaced
    by one that drops everything, each of them fails."""
    from polymatch_ros.ros import wire

    examples, outcome, decoders = FUZZERS[name]
    for decoder in decoders.split():
        monkeypatch.setattr(wire, decoder, lambda *args, **kw: (None, "dropped"))
    accepted = [ex for ex in examples if ex["expected"] == ACCEPTED]
    assert accepted
    for ex in accepted:
        with pytest.raises(AssertionError):
            outcome(ex["case"], ex["expected"])


@pytest.mark.parametrize("examples,outcome", [
    (POSE_EXAMPLES, "pose"), (TWIST_EXAMPLES, "twist"), (RECORD_EXAMPLES, "record"),
    (COMMAND_EXAMPLES, "command")])
def test_the_other_fuzzers_fail_on_a_decoder_that_drops_everything(examples, outcome,
                                                                   monkeypatch):
    from polymatch_ros.ros import wire
    from polymatch_ros.ros.wire import control

    monkeypatch.setattr(wire, "decode_pose_msg", lambda *args, **kw: (None, "dropped"))
    monkeypatch.setattr(wire, "decode_twist_msg", lambda *args, **kw: (None, "dropped"))
    monkeypatch.setattr(wire.RunRecord, "from_msg", classmethod(lambda cls, msg: None))
    monkeypatch.setattr(control, "parse_command", lambda msg: None)
    accepted = [ex for ex in examples if ex["expected"] == ACCEPTED]
    assert accepted
    for ex in accepted:
        with pytest.raises((AssertionError, pytest.fail.Exception)):
            if outcome in ("pose", "twist"):
                ex = dict(ex)
                parts = (ex.pop("pos"), ex.pop("quat")) if outcome == "pose" else \
                    (ex.pop("lin"), ex.pop("ang"))
                _geometry_outcome(outcome, ex["dim"], *parts, ex["stamp"], ex["frame"],
                                  ex["expected"])
            else:
                (_record_outcome if outcome == "record" else _command_outcome)(
                    ex["case"], ex["expected"])


# -- round trips: what an agent sends reads back as it was --------------------------------------

SHAPES = ((2, True), (2, False), (3, False), (4, False))


def _random_rows(grp, dim, n, seed):
    rng = np.random.default_rng(seed)
    mats = np.stack([_rotation(dim, seed + r) for r in range(n)])
    spins = rng.normal(size=(n, dim, dim))
    return (rng.normal(size=(n, dim)), mats, rng.normal(size=(n, dim)),
            spins - np.swapaxes(spins, 1, 2))


@pytest.mark.parametrize("dim,angle", SHAPES)
def test_stage_and_block_rows_round_trip_bit_for_bit(dim, angle):
    """encode_stage/encode_block -> decode gives each agent's values exactly, so lockstep
    computes with the numbers the centralised integrator uses."""
    from polymatch_interfaces.msg import StageRows
    from polymatch_ros.ros import wire

    grp, agents = _group(dim, angle), [9, 10, 11]
    x, mats, v, _ = _random_rows(grp, dim, 3, 3)
    angles = np.array([0.3, -2.0, 3.1])
    rot = np.array(angles) if angle else grp.from_matrices(mats)
    values = angles[:, None] if angle else mats.reshape(3, -1)
    for flags in (0, 1, 1 | 9 << 1):
        msg = wire.encode_block(StageRows(), RUN_ID, BLOCK, 5, 2, flags, 0.75, agents,
                                {"x": x, "v": v, "rot": values})
        rows, reason = wire.decode_block(msg, grp, dim, RUN_ID, BLOCK, K,
                                         wire.ROTATION_TOL, T_MAX)
        assert reason is None and rows.agents.tolist() == agents
        assert (rows.step, rows.stage, rows.flags, rows.t) == (5, 2, flags, 0.75)
        assert np.array_equal(rows.x, x) and np.array_equal(rows.v, v)
        assert np.array_equal(rows.rot, rot) if angle else \
            np.array_equal(grp.to_matrices(rows.rot), mats)
        one = wire.encode_stage(StageRows(), RUN_ID, 10, 5, 2, flags, 0.75,
                                {"x": x[1], "rot": values[1]})
        stage, reason = wire.decode_stage(one, grp, dim, RUN_ID, 10, wire.ROTATION_TOL, T_MAX)
        assert reason is None and (stage.step, stage.stage, stage.flags) == (5, 2, flags)
        assert np.array_equal(stage.x, x[1]) and stage.v is None
        assert np.array_equal(grp.to_matrices(stage.rot)[0], grp.to_matrices(
            grp.take(rot, [1]))[0])


@pytest.mark.parametrize("dim,angle", SHAPES)
def test_a_state_block_s_rows_are_each_agent_s_own_state_bit_for_bit(dim, angle):
    """encode_exchange_block -> decode gives, row by row, what each agent's own AgentState
    gives, and both hold the numbers sent (rotations as matrices; angles to an ulp)."""
    from polymatch_interfaces.msg import AgentState, AgentStateBlock
    from polymatch_ros.ros import wire

    grp, agents = _group(dim, angle), [8, 10]
    x, mats, v, spins = _random_rows(grp, dim, 2, 11)
    rot, w = grp.from_matrices(mats), grp.algebra_from_skew(spins)
    msg = wire.encode_exchange_block(AgentStateBlock(), grp, RUN_ID, BLOCK, 1.25, agents, x,
                                     rot, v, w)
    rows, reason = wire.decode_exchange_block(msg, grp, dim, RUN_ID, BLOCK, K, T_MAX)
    assert reason is None and [a for a, _ in rows] == agents
    for r, (a, got) in enumerate(rows):
        own = wire.encode_exchange(AgentState(), grp, RUN_ID, a, 1.25, x[r],
                                   grp.take(rot, [r]), v[r], grp.algebra_take(w, [r]))
        alone, reason = wire.decode_exchange(own, grp, dim, RUN_ID, a, T_MAX)
        assert reason is None and (got.t, got.key) == (alone.t, alone.key) == (1.25, 1.25e9)
        for field in ("x", "rot", "v", "w"):
            assert np.array_equal(getattr(got, field), getattr(alone, field))
        assert np.array_equal(got.x, x[r]) and np.array_equal(got.v, v[r])
        back = grp.to_matrices(got.rot)[0]
        assert np.max(np.abs(back - mats[r])) <= (4e-16 if angle else 0.0)
        assert np.max(np.abs(grp.algebra_to_skew(got.w)[0] - spins[r])) <= 0.0


@pytest.mark.parametrize("dim", [2, 3, 4, 5])
def test_an_agent_s_pose_and_twist_read_back_lemma_2_1(dim):
    """pose_message/twist_message -> decode: the centroid and velocity exactly, the rotation
    in SO(d) and equal to the one sent (through the quaternion for d <= 3: to round-off)."""
    from polymatch_ros.ros import wire

    grp = _group(dim)
    x, mats, v, spins = _random_rows(grp, dim, 1, 2)
    got, reason = wire.decode_pose_msg(wire.pose_message(grp, 1.5, x[0], grp.from_matrices(mats),
                                                         "world"), grp, dim, "world", T_MAX)
    assert reason is None and got.t == 1.5 and np.array_equal(got.vec, x[0])
    _in_so_d(grp.to_matrices(got.rot)[0])
    assert np.max(np.abs(grp.to_matrices(got.rot)[0] - mats[0])) < 1e-14
    got, reason = wire.decode_twist_msg(wire.twist_message(grp, 1.5, v[0],
                                                           grp.algebra_from_skew(spins), "world"),
                                        grp, dim, "world", T_MAX)
    assert reason is None and np.array_equal(got.vec, v[0])
    assert np.array_equal(grp.algebra_to_skew(got.rot)[0], spins[0])


def test_a_run_record_reads_back_as_it_was_sent():
    from polymatch_ros.ros import wire

    for rec in (wire.RunRecord(role="agent", mode="lockstep", t=2.5, agents=(3, 4), steps=40,
                               rounds=160, ms_per_round={"publish": 0.25, "wait": 1.5},
                               dropped={"non-finite value": 2}, peers=(0, 1), run_id=RUN_ID,
                               clock_offsets={1: -0.004}, resumed_at=12, node="/p/a"),
                wire.RunRecord(role="monitor", mode="realtime", t=9.0, diameter=0.125,
                               agents_heard=8, reports=90, matched_after=3.5,
                               first_round_at=1.7e9, max_rss_mb=80.5, run_id=2**64 - 1)):
        assert wire.RunRecord.from_msg(rec.to_msg()) == rec


def test_a_flood_of_drops_is_counted_in_full_and_warned_once_a_second_per_reason():
    """Every dropped message is counted; the warnings are throttled before the logger is
    called (a flood must not cost a logger call per message)."""
    from polymatch_ros.ros.wire.intake import DropCounter

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
