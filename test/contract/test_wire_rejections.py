"""Every way a decoder of the run's messages refuses one, reached on purpose, and every valid
message accepted with the values put in.

One hand-made ``polymatch_interfaces`` (or ``geometry_msgs``) message per reason, for each
decoder: lockstep stage rows of one agent and of a block (``stage_rows``), an agent's state and a
block of states (``exchange``), poses and velocities (``motion``: PoseStamped/TwistStamped for
d <= 3, PoseNd/TwistNd for d >= 4), the run record (``RunRecord.from_msg``) and the control
command (``parse_command``).  Each is dropped with exactly its reason; the unchanged message of
each kind is accepted, its values equal to the numbers written here (rotations built here:
scipy's ``Rotation`` in 3-D, cos/sin in the plane, Givens products in 4-D).  Messages are built
directly (no DDS).  test_wire_fuzz.py throws random messages at the same decoders.
"""

import math

import numpy as np
import pytest
from ros_harness import needs_ros
from scipy.spatial.transform import Rotation

pytestmark = needs_ros

RUN_ID, AGENT, T_MAX = 77, 3, 30.0
BLOCK, K = 2, 4                      # block 2 of 4 agents: agents 8 .. 11
NAN, INF = math.nan, math.inf
ABOVE_MAX = math.nextafter(1e100, INF)   # the first float past the bound 1e100 of the .msg files

R3 = Rotation.from_rotvec([0.3, -0.2, 0.5]).as_matrix()     # rotations in SO(3), by scipy
R3B = Rotation.from_rotvec([-1.0, 0.4, 2.0]).as_matrix()
REFLECTION3 = np.diag([-1.0, 1.0, 1.0]) @ R3                 # orthogonal, det -1
TILTED3 = (1.0 + 1e-3) * R3                                   # |O^T O - I| ~ 2e-3
SPIN = np.array([[0.0, -0.5, 0.25], [0.5, 0.0, -1.0], [-0.25, 1.0, 0.0]])   # W_i, skew
NOT_SKEW = SPIN + np.diag([0.0, 0.0, 0.5])


def _group(dim, angle=False):
    from polymatch_ros.core.so import SO2, SO3, SOn

    if dim == 2 and angle:
        return SO2()
    return SO3() if dim == 3 else SOn(dim)


def _flat(*mats):
    return [float(v) for m in mats for v in np.asarray(m).ravel()]


def _plane(angle):
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s], [s, c]])


def _givens(dim, i, j, angle):
    g = np.eye(dim)
    g[i, i] = g[j, j] = math.cos(angle)
    g[i, j], g[j, i] = -math.sin(angle), math.sin(angle)
    return g


def _stamp(msg, stamp, frame):
    msg.header.stamp.sec, msg.header.stamp.nanosec = stamp
    msg.header.frame_id = frame
    return msg


def _mats(grp, rot):
    return grp.to_matrices(rot)


# -- lockstep stage rows of one agent (stage_rows.decode_stage) ------------------------------

STAGE = dict(run_id=RUN_ID, sender=AGENT, step=4, stage=1, stop=False, stop_step=-1, t=1.25,
             agents=[AGENT], centroids=[0.5, -1.0, 2.0], velocities=[], rotations=_flat(R3))


def _stage_msg(**changes):
    from polymatch_interfaces.msg import StageRows

    return StageRows(**{**STAGE, **changes})


def _decode_stage(msg, dim=3, angle=False, tol=None):
    from polymatch_ros.ros import wire

    return wire.decode_stage(msg, _group(dim, angle), dim, RUN_ID, AGENT,
                             tol or wire.ROTATION_TOL, T_MAX)


STAGE_CASES = [  # (what, changed fields, reason)
    ("another run", {"run_id": RUN_ID + 1}, "unknown sender (run id)"),
    ("another sender", {"sender": AGENT + 1}, "unknown sender (agent index)"),
    ("a row of another agent", {"agents": [AGENT + 1]}, "unknown sender (agent index)"),
    ("two rows", {"agents": [AGENT, AGENT], "centroids": [0.0] * 6,
                  "rotations": _flat(R3, R3)}, "unknown sender (agent index)"),
    ("no rows", {"agents": []}, "malformed layout"),
    ("negative time", {"t": -0.5}, "stamp outside the run"),
    ("time past t_end", {"t": T_MAX + 2e-6}, "stamp outside the run"),
    ("NaN time", {"t": NAN}, "stamp outside the run"),
    ("infinite time", {"t": INF}, "stamp outside the run"),
    ("a short centroid", {"centroids": [0.5, -1.0]}, "malformed layout"),
    ("a long velocity", {"velocities": [0.1] * 4}, "malformed layout"),
    ("no rotation", {"rotations": []}, "malformed layout"),
    ("a rotation of 8 entries", {"rotations": _flat(R3)[:8]}, "malformed layout"),
    ("NaN in the centroid", {"centroids": [0.5, NAN, 2.0]}, "non-finite value"),
    ("-infinity in the rotation", {"rotations": [-INF] + _flat(R3)[1:]}, "non-finite value"),
    ("a velocity above 1e100", {"velocities": [0.0, ABOVE_MAX, 0.0]}, "value out of range"),
    ("a tilted rotation", {"rotations": _flat(TILTED3)}, "rotation not orthogonal"),
    ("a reflection", {"rotations": _flat(REFLECTION3)}, "rotation not in SO(d)"),
]


@pytest.mark.parametrize("what,changes,reason", STAGE_CASES, ids=[c[0] for c in STAGE_CASES])
def test_stage_rows_are_dropped_with_their_reason(what, changes, reason):
    assert _decode_stage(_stage_msg(**changes)) == (None, reason)


def test_the_unchanged_stage_rows_are_accepted_with_their_values():
    stage, reason = _decode_stage(_stage_msg())
    assert reason is None
    assert (stage.agent, stage.step, stage.stage, stage.flags, stage.t) == (3, 4, 1, 0, 1.25)
    assert stage.x.tolist() == [0.5, -1.0, 2.0] and stage.v is None
    assert np.array_equal(_mats(_group(3), stage.rot)[0], R3)
    edge = {"t": T_MAX + 1e-7, "centroids": [], "velocities": [1e100, -1e100, 0.0],
            "stop": True, "stop_step": 9}          # within the slack, at the bound, stopping
    stage, reason = _decode_stage(_stage_msg(**edge))
    assert reason is None and stage.x is None and stage.v.tolist() == [1e100, -1e100, 0.0]
    assert stage.flags & 1 and stage.flags >> 1 == 9
    stage, reason = _decode_stage(_stage_msg(centroids=[0.5, -1.0], rotations=[2.5]), 2, True)
    assert reason is None and stage.rot.tolist() == [2.5]     # 2-D integrators' angle


def test_a_projection_stage_is_checked_loosely_but_never_a_reflection_lemma_2_1():
    """Projection integrators' intermediate stages are off SO(d) by their step's error; a
    reflection is no such error (Lemma 2.1: the flow stays in SO(d), det = +1)."""
    from polymatch_ros.ros import wire

    stage, reason = _decode_stage(_stage_msg(rotations=_flat(TILTED3)),
                                  tol=wire.PROJECTION_STAGE_TOL)
    assert reason is None and np.array_equal(_mats(_group(3), stage.rot)[0], TILTED3)
    assert _decode_stage(_stage_msg(rotations=_flat(REFLECTION3)),
                         tol=wire.PROJECTION_STAGE_TOL) == (None, "rotation not in SO(d)")


# -- lockstep stage rows of a block (stage_rows.decode_block) ------------------------------

ROWS_X = [0.5, -1.0, 2.0, 1.5, 0.0, -2.0]
BLOCK_STAGE = {**STAGE, "sender": BLOCK, "agents": [8, 9], "centroids": ROWS_X,
               "rotations": _flat(R3, R3B)}


def _block_msg(**changes):
    from polymatch_interfaces.msg import StageRows

    return StageRows(**{**BLOCK_STAGE, **changes})


def _decode_block(msg):
    from polymatch_ros.ros import wire

    return wire.decode_block(msg, _group(3), 3, RUN_ID, BLOCK, K, wire.ROTATION_TOL, T_MAX)


FIVE = {"agents": [8, 9, 10, 11, 8], "centroids": [0.0] * 15, "rotations": _flat(*[R3] * 5)}
BLOCK_CASES = [
    ("another run", {"run_id": 0}, "unknown sender (run id)"),
    ("another block", {"sender": BLOCK + 1}, "unknown sender (agent index)"),
    ("an agent below the block", {"agents": [7, 8]}, "unknown sender (agent index)"),
    ("an agent past the block", {"agents": [8, 12]}, "unknown sender (agent index)"),
    ("an agent twice", {"agents": [9, 9]}, "unknown sender (agent index)"),
    ("more rows than the block has agents", FIVE, "unknown sender (agent index)"),
    ("no rows", {"agents": []}, "malformed layout"),
    ("time past t_end", {"t": 31.0}, "stamp outside the run"),
    ("centroids one short", {"centroids": ROWS_X[:5]}, "malformed layout"),
    ("rotations one short", {"rotations": _flat(R3, R3B)[:17]}, "malformed layout"),
    ("NaN in the second row", {"centroids": ROWS_X[:4] + [NAN, 0.0]}, "non-finite value"),
    ("the second rotation above 1e100", {"rotations": _flat(R3) + [-ABOVE_MAX] * 9},
     "value out of range"),
    ("the second rotation tilted", {"rotations": _flat(R3, TILTED3)},
     "rotation not orthogonal"),
    ("the second rotation a reflection", {"rotations": _flat(R3, REFLECTION3)},
     "rotation not in SO(d)"),
]


@pytest.mark.parametrize("what,changes,reason", BLOCK_CASES, ids=[c[0] for c in BLOCK_CASES])
def test_block_stage_rows_are_dropped_whole_with_their_reason(what, changes, reason):
    assert _decode_block(_block_msg(**changes)) == (None, reason)


def test_the_unchanged_block_stage_rows_are_accepted_with_their_values():
    rows, reason = _decode_block(_block_msg())
    assert reason is None and rows.agents.tolist() == [8, 9] and rows.t == 1.25
    assert rows.x.tolist() == [ROWS_X[:3], ROWS_X[3:]] and rows.v is None
    assert np.array_equal(_mats(_group(3), rows.rot), np.stack([R3, R3B]))
    rows, reason = _decode_block(_block_msg(agents=[11, 8, 10], centroids=[0.0] * 9,
                                            rotations=_flat(R3B, R3, R3)))
    assert reason is None and rows.agents.tolist() == [11, 8, 10]    # any order in the block


# -- an agent's state (exchange.decode_exchange) ----------------------------------------------

STATE = dict(run_id=RUN_ID, agent=AGENT, centroid=[0.5, -1.0, 2.0], rotation=_flat(R3),
             velocity=[0.1, 0.2, -0.3], angular_velocity=_flat(SPIN))


def _state_msg(stamp=(1, 250_000_000), frame="world", **changes):
    from polymatch_interfaces.msg import AgentState

    return _stamp(AgentState(**{**STATE, **changes}), stamp, frame)


def _decode_state(msg, dim=3, angle=False):
    from polymatch_ros.ros import wire

    return wire.decode_exchange(msg, _group(dim, angle), dim, RUN_ID, AGENT, T_MAX)


STATE_CASES = [
    ("another run", {"run_id": RUN_ID + 1}, "unknown sender (run id)"),
    ("another agent", {"agent": AGENT + 1}, "unknown sender (agent index)"),
    ("nanoseconds of a whole second", {"stamp": (1, 10**9)}, "malformed header"),
    ("a negative stamp", {"stamp": (-1, 0)}, "stamp outside the run"),
    ("stamped past t_end", {"stamp": (30, 2000)}, "stamp outside the run"),
    ("no centroid", {"centroid": []}, "malformed layout"),
    ("a short centroid", {"centroid": [0.5, -1.0]}, "malformed layout"),
    ("a rotation of 8 entries", {"rotation": _flat(R3)[:8]}, "malformed layout"),
    ("a velocity without angular velocity", {"angular_velocity": []}, "malformed layout"),
    ("an angular velocity without velocity", {"velocity": []}, "malformed layout"),
    ("a long velocity", {"velocity": [0.1] * 4}, "malformed layout"),
    ("NaN in the centroid", {"centroid": [NAN, -1.0, 2.0]}, "non-finite value"),
    ("infinity in W", {"angular_velocity": [0.0, INF] + _flat(SPIN)[2:]}, "non-finite value"),
    ("a velocity above 1e100", {"velocity": [0.1, 0.2, ABOVE_MAX]}, "value out of range"),
    ("a tilted rotation", {"rotation": _flat(TILTED3)}, "rotation not in SO(d)"),
    ("a reflection", {"rotation": _flat(REFLECTION3)}, "rotation not in SO(d)"),
    ("W not skew", {"angular_velocity": _flat(NOT_SKEW)}, "angular velocity not skew"),
]


@pytest.mark.parametrize("what,changes,reason", STATE_CASES, ids=[c[0] for c in STATE_CASES])
def test_agent_state_is_dropped_with_its_reason(what, changes, reason):
    assert _decode_state(_state_msg(**changes)) == (None, reason)


def test_the_unchanged_agent_state_is_accepted_with_its_values():
    grp = _group(3)
    got, reason = _decode_state(_state_msg())
    assert reason is None and (got.t, got.key) == (1.25, 1_250_000_000)
    assert got.x.tolist() == [0.5, -1.0, 2.0] and got.v.tolist() == [0.1, 0.2, -0.3]
    assert np.array_equal(_mats(grp, got.rot)[0], R3)
    assert np.array_equal(grp.algebra_to_skew(got.w)[0], SPIN)
    first = {"velocity": [], "angular_velocity": [], "stamp": (30, 999),   # within the slack
             "centroid": [1e100, 0.0, -1e100]}                            # at the bound
    got, reason = _decode_state(_state_msg(**first))
    assert reason is None and got.v is None and got.w is None
    assert got.x.tolist() == [1e100, 0.0, -1e100] and got.key == 30_000_000_999


@pytest.mark.parametrize("angle", [2.5, -3.0, 0.0])
def test_a_planar_state_is_read_as_its_angle(angle):
    """The state carries the matrix [[cos, -sin], [sin, cos]]; a reader that computes with
    angles (the monitor, the runner) gets the angle back to an ulp."""
    got, reason = _decode_state(_state_msg(centroid=[0.5, -1.0], rotation=_flat(_plane(angle)),
                                           velocity=[], angular_velocity=[]), 2, True)
    assert reason is None and abs(got.rot[0] - angle) <= 4.5e-16


# -- a block of states (exchange.decode_exchange_block) ---------------------------------------

STATE_BLOCK = dict(run_id=RUN_ID, block=BLOCK, agents=[8, 9], centroids=ROWS_X,
                   rotations=_flat(R3, R3B), velocities=[0.1, 0.2, -0.3, 0.0, 1.0, 0.5],
                   angular_velocities=_flat(SPIN, -2.0 * SPIN))


def _state_block_msg(stamp=(1, 250_000_000), **changes):
    from polymatch_interfaces.msg import AgentStateBlock

    return _stamp(AgentStateBlock(**{**STATE_BLOCK, **changes}), stamp, "world")


def _decode_state_block(msg):
    from polymatch_ros.ros import wire

    return wire.decode_exchange_block(msg, _group(3), 3, RUN_ID, BLOCK, K, T_MAX)


STATE_BLOCK_CASES = [
    ("another run", {"run_id": RUN_ID + 1}, "unknown sender (run id)"),
    ("another block", {"block": BLOCK - 1}, "unknown sender (agent index)"),
    ("an agent below the block", {"agents": [7, 9]}, "unknown sender (agent index)"),
    ("an agent past the block", {"agents": [8, 12]}, "unknown sender (agent index)"),
    ("an agent twice", {"agents": [8, 8]}, "unknown sender (agent index)"),
    ("more rows than the block has agents", {"agents": [8, 9, 10, 11, 9]},
     "unknown sender (agent index)"),
    ("no rows", {"agents": []}, "malformed layout"),
    ("nanoseconds of a whole second", {"stamp": (0, 4_000_000_000)}, "malformed header"),
    ("stamped past t_end", {"stamp": (31, 0)}, "stamp outside the run"),
    ("centroids one short", {"centroids": ROWS_X[:5]}, "malformed layout"),
    ("velocities without angular velocities", {"angular_velocities": []}, "malformed layout"),
    ("NaN in the second row", {"centroids": ROWS_X[:5] + [NAN]}, "non-finite value"),
    ("the second velocity above 1e100", {"velocities": [0.0] * 5 + [-ABOVE_MAX]},
     "value out of range"),
    ("the second rotation tilted", {"rotations": _flat(R3, TILTED3)}, "rotation not in SO(d)"),
    ("the second rotation a reflection", {"rotations": _flat(R3, REFLECTION3)},
     "rotation not in SO(d)"),
    ("the second W not skew", {"angular_velocities": _flat(SPIN, NOT_SKEW)},
     "angular velocity not skew"),
]


@pytest.mark.parametrize("what,changes,reason", STATE_BLOCK_CASES,
                         ids=[c[0] for c in STATE_BLOCK_CASES])
def test_state_block_is_dropped_whole_with_its_reason(what, changes, reason):
    assert _decode_state_block(_state_block_msg(**changes)) == (None, reason)


def test_the_unchanged_state_block_is_accepted_with_its_values():
    grp = _group(3)
    rows, reason = _decode_state_block(_state_block_msg())
    assert reason is None and [a for a, _ in rows] == [8, 9]
    for r, (_, got) in enumerate(rows):
        assert (got.t, got.key) == (1.25, 1_250_000_000)
        assert got.x.tolist() == ROWS_X[3 * r:3 * r + 3]
        assert got.v.tolist() == STATE_BLOCK["velocities"][3 * r:3 * r + 3]
        assert np.array_equal(_mats(grp, got.rot)[0], (R3, R3B)[r])
        assert np.array_equal(grp.algebra_to_skew(got.w)[0], (SPIN, -2.0 * SPIN)[r])


# -- poses and velocities, d <= 3 (geometry_msgs) ---------------------------------------------

QUAT = (0.0, 0.0, math.sin(0.2), math.cos(0.2))   # a turn of 0.4 rad about z


def _pose(dim, x=None, quat=None, frame="world", stamp=(1, 0)):
    from geometry_msgs.msg import PoseStamped

    msg = PoseStamped()
    msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = x or (0.5, -1.0, 0.0)
    o = msg.pose.orientation
    o.x, o.y, o.z, o.w = quat or QUAT
    return _stamp(msg, stamp, frame)


def _twist(dim, lin=None, ang=None, frame="world", stamp=(1, 0)):
    from geometry_msgs.msg import TwistStamped

    msg = TwistStamped()
    msg.twist.linear.x, msg.twist.linear.y, msg.twist.linear.z = lin or (0.5, -1.0, 0.0)
    msg.twist.angular.x, msg.twist.angular.y, msg.twist.angular.z = ang or (0.0, 0.0, 0.3)
    return _stamp(msg, stamp, frame)


HALF = math.sqrt(0.5)
GEOMETRY_CASES = [  # (what, kind, dimension, message fields, reason)
    ("NaN position", "pose", 3, {"x": (math.nan, 0.0, 0.0)}, "non-finite value"),
    ("infinite quaternion", "pose", 3, {"quat": (0.0, 0.0, 0.0, math.inf)}, "non-finite value"),
    ("position above 1e100", "pose", 3, {"x": (0.0, ABOVE_MAX, 0.0)}, "value out of range"),
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
    ("pose stamped before the run", "pose", 2, {"stamp": (-1, 0)}, "stamp outside the run"),
    ("corrupt contents named before the frame", "pose", 3,
     {"x": (math.nan, 0.0, 0.0), "frame": "map"}, "non-finite value"),
    ("NaN angular velocity", "twist", 3, {"ang": (0.0, math.nan, 0.0)}, "non-finite value"),
    ("-infinite velocity", "twist", 2, {"lin": (-math.inf, 0.0, 0.0)}, "non-finite value"),
    ("velocity above 1e100", "twist", 3, {"lin": (0.0, 0.0, -ABOVE_MAX)}, "value out of range"),
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


def _decode_motion(kind, dim, msg, angle=False):
    from polymatch_ros.ros import wire

    decode = wire.decode_pose_msg if kind == "pose" else wire.decode_twist_msg
    return decode(msg, _group(dim, angle), dim, "world", T_MAX)


@pytest.mark.parametrize("what,kind,dim,fields,reason", GEOMETRY_CASES,
                         ids=[c[0] for c in GEOMETRY_CASES])
def test_geometry_message_is_dropped_with_its_reason(what, kind, dim, fields, reason):
    msg = (_pose if kind == "pose" else _twist)(dim, **fields)
    assert _decode_motion(kind, dim, msg) == (None, reason)


@pytest.mark.parametrize("dim,angle", [(2, True), (2, False), (3, False)])
def test_the_unchanged_geometry_messages_are_accepted_with_their_values(dim, angle):
    """QUAT is a turn of 0.4 rad about z: cos/sin in the plane; in 3-D its matrix too."""
    grp = _group(dim, angle)
    turn = np.eye(3)
    turn[:2, :2] = _plane(0.4)
    got, reason = _decode_motion("pose", dim, _pose(dim), angle)
    assert reason is None and got.t == 1.0 and got.vec.tolist() == [0.5, -1.0, 0.0][:dim]
    assert np.max(np.abs(_mats(grp, got.rot)[0] - turn[:dim, :dim])) < 1e-15
    got, reason = _decode_motion("twist", dim, _twist(dim), angle)
    assert reason is None and got.t == 1.0 and got.vec.tolist() == [0.5, -1.0, 0.0][:dim]
    spin = np.array([[0.0, -0.3, 0.0], [0.3, 0.0, 0.0], [0.0, 0.0, 0.0]])
    assert np.array_equal(grp.algebra_to_skew(got.rot)[0], spin[:dim, :dim])


# -- poses and velocities, d >= 4 (PoseNd, TwistNd) -------------------------------------------

R4 = _givens(4, 0, 1, 0.7) @ _givens(4, 2, 3, -1.1) @ _givens(4, 1, 3, 0.4)
SPIN4 = np.array([[0.0, -0.3, 0.1, 0.0], [0.3, 0.0, 0.0, -0.7],
                  [-0.1, 0.0, 0.0, 0.2], [0.0, 0.7, -0.2, 0.0]])
ND = {"pose": ("position", "orientation", R4), "twist": ("linear", "angular", SPIN4)}
POSITION4 = [0.5, -1.0, 2.0, 0.0]


def _nd_msg(kind, stamp=(1, 0), frame="world", vec=None, mat=None):
    from polymatch_interfaces.msg import PoseNd, TwistNd

    vector, matrix, valid = ND[kind]
    msg = (PoseNd if kind == "pose" else TwistNd)()
    setattr(msg, vector, POSITION4 if vec is None else vec)
    setattr(msg, matrix, _flat(valid) if mat is None else mat)
    return _stamp(msg, stamp, frame)


ND_CASES = [  # (what, kind, message arguments, reason)
    ("pose in another frame", "pose", {"frame": "map"}, "unknown frame 'map'"),
    ("twist in another frame", "twist", {"frame": "World"}, "unknown frame 'World'"),
    ("nanoseconds of a whole second", "pose", {"stamp": (2, 10**9)}, "malformed header"),
    ("stamped past t_end", "twist", {"stamp": (30, 2000)}, "stamp outside the run"),
    ("stamped before the run", "pose", {"stamp": (-3, 5)}, "stamp outside the run"),
    ("no position", "pose", {"vec": []}, "malformed layout"),
    ("a short position", "pose", {"vec": POSITION4[:3]}, "malformed layout"),
    ("a long velocity", "twist", {"vec": POSITION4 + [1.0]}, "malformed layout"),
    ("an orientation of 15 entries", "pose", {"mat": _flat(R4)[:15]}, "malformed layout"),
    ("NaN position", "pose", {"vec": [0.5, NAN, 2.0, 0.0]}, "non-finite value"),
    ("infinite angular velocity", "twist", {"mat": [INF] + _flat(SPIN4)[1:]},
     "non-finite value"),
    ("position above 1e100", "pose", {"vec": [0.5, ABOVE_MAX, 2.0, 0.0]}, "value out of range"),
    ("a tilted rotation", "pose", {"mat": _flat((1.0 + 1e-3) * R4)}, "rotation not in SO(d)"),
    ("a reflection", "pose", {"mat": _flat(np.diag([1.0, 1.0, 1.0, -1.0]) @ R4)},
     "rotation not in SO(d)"),
    ("angular velocity not skew", "twist", {"mat": _flat(np.eye(4))},
     "angular velocity not skew"),
]


@pytest.mark.parametrize("what,kind,arguments,reason", ND_CASES, ids=[c[0] for c in ND_CASES])
def test_pose_and_twist_nd_are_dropped_with_their_reason(what, kind, arguments, reason):
    assert _decode_motion(kind, 4, _nd_msg(kind, **arguments)) == (None, reason)


@pytest.mark.parametrize("kind", ["pose", "twist"])
def test_the_unchanged_pose_and_twist_nd_are_accepted_with_their_values(kind):
    grp = _group(4)
    got, reason = _decode_motion(kind, 4, _nd_msg(kind))
    assert reason is None and got.t == 1.0 and got.vec.tolist() == POSITION4
    back = _mats(grp, got.rot)[0] if kind == "pose" else grp.algebra_to_skew(got.rot)[0]
    assert np.array_equal(back, ND[kind][2])


# -- the run record (RunRecord.from_msg) ------------------------------------------------------


def _record_msg(**changes):
    from polymatch_interfaces.msg import NamedValue, ReasonCount, RunRecord

    fields = dict(run_id=RUN_ID, role="agent", mode="lockstep", t=2.5, agents=[3, 4],
                  finished=True, steps=40, rounds=160, rounds_per_second=812.5,
                  ms_per_round=[NamedValue(name="publish", value=0.25)], late_ticks=0,
                  matched_after=NAN, dropped=[ReasonCount(reason="non-finite value", count=2)],
                  diameter=NAN, agents_heard=0, reports=0, peers=[0, 1, 2],
                  stage_subscriptions=2, clock_offsets=[NamedValue(name="1", value=-0.004)],
                  n_agents=8, node="/polymatch/agents_3_4", resumed_at=-1,
                  first_round_at=1.7e9, max_rss_mb=80.5)
    return RunRecord(**{**fields, **changes})


def test_the_unchanged_run_record_is_accepted_with_its_values():
    from polymatch_ros.ros import wire

    rec = wire.RunRecord.from_msg(_record_msg())
    assert rec == wire.RunRecord(
        role="agent", mode="lockstep", t=2.5, agents=(3, 4), finished=True, steps=40,
        rounds=160, rounds_per_second=812.5, ms_per_round={"publish": 0.25}, late_ticks=0,
        matched_after=None, dropped={"non-finite value": 2}, diameter=None, agents_heard=0,
        reports=0, peers=(0, 1, 2), stage_subscriptions=2, clock_offsets={1: -0.004},
        n_agents=8, node="/polymatch/agents_3_4", resumed_at=None, run_id=RUN_ID,
        first_round_at=1.7e9, max_rss_mb=80.5)
    rec = wire.RunRecord.from_msg(_record_msg(role="monitor", diameter=0.125, resumed_at=12,
                                              matched_after=3.5))
    assert (rec.role, rec.diameter, rec.resumed_at, rec.matched_after) == \
        ("monitor", 0.125, 12, 3.5)


RECORD_CASES = [
    ("an unknown role", {"role": "robot"}),
    ("no role", {"role": ""}),
    ("NaN time", {"t": NAN}),
    ("infinite time", {"t": INF}),
    ("-infinite time", {"t": -INF}),
]


@pytest.mark.parametrize("what,changes", RECORD_CASES, ids=[c[0] for c in RECORD_CASES])
def test_run_record_is_refused(what, changes):
    from polymatch_ros.ros import wire

    assert wire.RunRecord.from_msg(_record_msg(**changes)) is None


def test_a_run_record_with_a_clock_offset_of_no_peer_is_refused():
    from polymatch_interfaces.msg import NamedValue
    from polymatch_ros.ros import wire

    msg = _record_msg(clock_offsets=[NamedValue(name="agent_1", value=0.5)])
    assert wire.RunRecord.from_msg(msg) is None


# -- the control command (wire.control.parse_command) -----------------------------------------

EPOCH = (1000, 250_000_000)   # 1000.25 s since the epoch


def _command(command, epoch=EPOCH):
    from builtin_interfaces.msg import Time

    from polymatch_interfaces.msg import ControlCommand

    return ControlCommand(command=command, epoch=Time(sec=epoch[0], nanosec=epoch[1]))


@pytest.mark.parametrize("constant,expected", [
    ("START", ("start", 1000.25)), ("STOP", ("stop", None)), ("PAUSE", ("pause", 1000.25)),
    ("RESUME", ("resume", 1000.25)), ("RESET", ("reset", 1000.25)),
    ("RECEIVED", ("received", None)),
])
def test_every_control_command_of_the_msg_file_is_accepted(constant, expected):
    from polymatch_interfaces.msg import ControlCommand
    from polymatch_ros.ros.wire.control import parse_command

    assert parse_command(_command(getattr(ControlCommand, constant))) == expected


COMMAND_CASES = [  # (what, command, epoch)
    ("the first unknown command", 6, EPOCH),
    ("the last uint8", 255, EPOCH),
    ("a pause without its epoch", 2, (0, 0)),
    ("a reset before 1970", 4, (-5, 0)),
    ("a start with nanoseconds of a whole second", 0, (1000, 10**9)),
    ("a stop with nanoseconds of a whole second", 1, (0, 2**32 - 1)),
]


@pytest.mark.parametrize("what,command,epoch", COMMAND_CASES, ids=[c[0] for c in COMMAND_CASES])
def test_control_command_is_refused(what, command, epoch):
    from polymatch_ros.ros.wire.control import parse_command

    assert parse_command(_command(command, epoch)) is None
