"""Messages on the wire: poses, velocities and lockstep stages, built and validated here only.

``agent_<i>/pose``   d <= 3: ``geometry_msgs/PoseStamped``: position = centroid (z = 0 in 2-D),
                     orientation = quaternion of O_i (about z in 2-D), header.stamp = simulated
                     time, header.frame_id = frame (default ``world``).  d >= 4:
                     ``std_msgs/Float64MultiArray`` with layout dims
                     [("t", 1), ("centroid", d), ("rotation_row_major", d*d)].
``agent_<i>/twist``  second order only.  d <= 3: ``geometry_msgs/TwistStamped`` (linear =
                     centroid velocity, angular = spatial angular velocity vee(W_i) of (A-1)).
                     d >= 4: Float64MultiArray dims [("t", 1), ("velocity", d),
                     ("angular_row_major", d*d)].
``agent_<i>/stage``  lockstep only: ``std_msgs/Float64MultiArray``, no layout dims (they cost a
                     Python object each on every publish and take), data = [format 2, run id,
                     agent, step, stage, flags, t, mask] then x (d) if mask & 1, v (d) if
                     mask & 2, rot (r) (mask & 4, always); rot is the core's representation
                     (angle in 2-D, row-major matrix otherwise), so the distributed run computes
                     with exactly the numbers the centralised one does.

Every decoder returns ``(value, None)`` or ``(None, reason)``, never raises: a value is finite,
within MAX_ABS, stamped inside the run, its rotation in SO(d) (Lemma 2.1: the flow keeps O_i
orthogonal); agents and the monitor drop and count a message with a reason, never use it.
"""

import math
from dataclasses import dataclass

import numpy as np

STAGE_FORMAT = 2
HEADER = 8
FLAG_STOP = 1
FIELDS = (("x", 1), ("v", 2), ("rot", 4))  # field, bit in the header's field mask, in wire order

# One tolerance for every rotation on the wire: the quaternion's norm, a matrix's orthogonality
# defect, a planar pose's out-of-plane parts, an angular velocity's skewness.  Agents send
# rotations that are orthogonal to round-off (~1e-15) in float64 messages, so a defect above
# 1e-9 cannot come from a correct agent; a looser bound (float32 sources) would let rotations
# through that the sums then carry.
ROTATION_TOL = 1e-9
# Projection integrators' intermediate stages are not orthogonal (they are projected at the
# end of the step): their stage messages are checked only for gross corruption.
PROJECTION_STAGE_TOL = 0.5
# Beyond this a coordinate's square and the ensemble's sums of squares overflow float64.
MAX_ABS = 1e100
# Stamps may exceed t_end by round-off of the time grid.
STAMP_SLACK = 1e-6


def stamp_of(t):
    """Simulated time (s) -> (sec, nanosec) for builtin_interfaces/Time."""
    ns = int(round(t * 1e9))
    return ns // 1_000_000_000, ns % 1_000_000_000


def time_key(sec, nanosec):
    return int(sec) * 1_000_000_000 + int(nanosec)


def rot_values(grp, g):
    """One rotation (a one-row group array) -> the list of floats the stage message carries."""
    if grp.name == "angle":
        return [float(g[0])]
    return grp.to_matrices(g)[0].ravel().tolist()


def rot_size(grp):
    return 1 if grp.name == "angle" else grp.dim * grp.dim


def rot_from_values(grp, values):
    if grp.name == "angle":
        return np.array([values[0]], dtype=float)
    d = grp.dim
    return grp.from_matrices(np.asarray(values, dtype=float).reshape(1, d, d))


def orthogonality(mat):
    return float(np.max(np.abs(mat.T @ mat - np.eye(len(mat)))))


def _bad_numbers(values):
    """The reason a vector of numbers is unusable, or None."""
    if not np.all(np.isfinite(values)):
        return "non-finite value"
    if values.size and np.max(np.abs(values)) > MAX_ABS:
        return "value out of range"
    return None


def _bad_stamp(t, t_max):
    if not math.isfinite(t) or t < 0.0 or (t_max is not None and t > t_max + STAMP_SLACK):
        return "stamp outside the run"
    return None


# -- stage messages ------------------------------------------------------------------


@dataclass
class Stage:
    agent: int
    step: int
    stage: int
    flags: int
    t: float
    x: np.ndarray = None
    v: np.ndarray = None
    rot: np.ndarray = None  # one-row group array


def encode_stage(msg, run_id, agent, step, stage, flags, t, fields):
    """Fill a Float64MultiArray with a stage: fields is a dict label -> values (x, v, rot)."""
    mask = 0
    body = []
    for label, bit in FIELDS:
        if label in fields:
            mask |= bit
            body.extend(fields[label])
    msg.data = [
        float(STAGE_FORMAT),
        float(run_id),
        float(agent),
        float(step),
        float(stage),
        float(flags),
        float(t),
        float(mask),
    ] + body
    return msg


def _stage_header(data, run_id, agent, t_max):
    """(step, stage, flags, t, mask) of a stage message's header, or the reason it is refused."""
    head = data[:HEADER]
    if (
        np.any(head[[0, 1, 2, 3, 4, 5, 7]] != np.round(head[[0, 1, 2, 3, 4, 5, 7]]))
        or np.any(head[[1, 2, 3, 4, 5, 7]] < 0)
        or np.any(np.abs(head) > 2.0**53)
    ):
        return None, "malformed header"
    if int(head[0]) != STAGE_FORMAT:
        return None, "unknown format"
    if int(head[1]) != int(run_id):
        return None, "unknown sender (run id)"
    if int(head[2]) != agent:
        return None, "unknown sender (agent index)"
    reason = _bad_stamp(float(head[6]), t_max)
    if reason:
        return None, reason
    return (int(head[3]), int(head[4]), int(head[5]), float(head[6]), int(head[7])), None


def decode_stage(msg, grp, dim, run_id, agent, rot_tol=ROTATION_TOL, t_max=None):
    """Float64MultiArray -> (Stage, None) or (None, reason)."""
    data = np.frombuffer(msg.data, dtype=float) if len(msg.data) else np.zeros(0)
    if len(data) < HEADER or msg.layout.dim or msg.layout.data_offset != 0:
        return None, "malformed layout"
    reason = _bad_numbers(data)
    if reason:
        return None, reason
    head, reason = _stage_header(data, run_id, agent, t_max)
    if head is None:
        return None, reason
    step, stage, flags, t, mask = head
    sizes = {"x": dim, "v": dim, "rot": rot_size(grp)}
    if (
        mask & ~7
        or not mask & 4
        or len(data) != HEADER + sum(sizes[f] for f, bit in FIELDS if mask & bit)
    ):
        return None, "malformed layout"
    out = Stage(agent, step, stage, flags, t)
    pos = HEADER
    for label, bit in FIELDS:
        if not mask & bit:
            continue
        values = data[pos : pos + sizes[label]]
        pos += sizes[label]
        if label == "rot":
            if grp.name != "angle" and orthogonality(values.reshape(grp.dim, grp.dim)) > rot_tol:
                return None, "rotation not orthogonal"
            out.rot = rot_from_values(grp, values)
        else:
            setattr(out, label, values.copy())
    return out, None


# -- poses and velocities --------------------------------------------------------------


def pose_fields(grp, x, g):
    """(position xyz, quaternion xyzw) of one agent for a PoseStamped (d <= 3)."""
    pos = np.zeros(3)
    pos[: len(x)] = x
    if grp.dim == 2:
        if grp.name == "angle":
            theta = float(g[0])
        else:
            mat = grp.to_matrices(g)[0]
            theta = math.atan2(mat[1, 0], mat[0, 0])
        quat = np.array([0.0, 0.0, math.sin(theta / 2), math.cos(theta / 2)])
    else:
        from scipy.spatial.transform import Rotation

        quat = Rotation.from_matrix(grp.to_matrices(g)[0]).as_quat()
    return pos, quat


def twist_fields(grp, v, w_row):
    """(linear xyz, angular xyz) of one agent's velocities for a TwistStamped (d <= 3)."""
    lin = np.zeros(3)
    lin[: len(v)] = v
    skew = grp.algebra_to_skew(w_row)[0]
    ang = (
        np.array([skew[2, 1], skew[0, 2], skew[1, 0]])
        if grp.dim == 3
        else np.array([0.0, 0.0, skew[1, 0]])
    )
    return lin, ang


def _array_message(t, vec, mat, labels):
    from std_msgs.msg import Float64MultiArray, MultiArrayDimension

    msg = Float64MultiArray()
    d = len(vec)
    msg.layout.dim = [
        MultiArrayDimension(label=labels[0], size=1, stride=1),
        MultiArrayDimension(label=labels[1], size=d, stride=d),
        MultiArrayDimension(label=labels[2], size=d * d, stride=d * d),
    ]
    msg.data = [float(t)] + [float(v) for v in vec] + [float(v) for v in np.asarray(mat).ravel()]
    return msg


def _stamped(cls, t, frame_id):
    msg = cls()
    msg.header.stamp.sec, msg.header.stamp.nanosec = stamp_of(t)
    msg.header.frame_id = frame_id
    return msg


def pose_message(grp, t, x, one, frame_id):
    """One agent's pose message at simulated time t (type by dimension: see the module doc)."""
    if grp.dim >= 4:
        return _array_message(
            t, x, grp.to_matrices(one)[0], ("t", "centroid", "rotation_row_major")
        )
    from geometry_msgs.msg import PoseStamped

    msg = _stamped(PoseStamped, t, frame_id)
    pos, quat = pose_fields(grp, x, one)
    msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = map(float, pos)
    o = msg.pose.orientation
    o.x, o.y, o.z, o.w = map(float, quat)
    return msg


def twist_message(grp, t, v, w_one, frame_id):
    """One agent's velocity message (centroid velocity, spatial angular velocity W_i)."""
    if grp.dim >= 4:
        return _array_message(
            t, v, grp.algebra_to_skew(w_one)[0], ("t", "velocity", "angular_row_major")
        )
    from geometry_msgs.msg import TwistStamped

    msg = _stamped(TwistStamped, t, frame_id)
    lin, ang = twist_fields(grp, v, w_one)
    msg.twist.linear.x, msg.twist.linear.y, msg.twist.linear.z = map(float, lin)
    msg.twist.angular.x, msg.twist.angular.y, msg.twist.angular.z = map(float, ang)
    return msg


def pose_to_state(grp, dim, position, quat):
    """PoseStamped contents -> ((x, one-row rotation), None) or (None, reason)."""
    p = np.asarray(position, dtype=float)
    q = np.asarray(quat, dtype=float)
    reason = _bad_numbers(np.concatenate([p, q]))
    if reason:
        return None, reason
    norm = float(np.linalg.norm(q))
    if abs(norm - 1.0) > ROTATION_TOL:
        return None, "quaternion far from unit norm"
    if dim == 2:
        if abs(p[2]) > ROTATION_TOL or abs(q[0]) > ROTATION_TOL or abs(q[1]) > ROTATION_TOL:
            return None, "not a planar pose"
        theta = 2.0 * math.atan2(q[2], q[3])
        mat = np.array([[[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]]])
        return (
            p[:2].copy(),
            grp.from_matrices(mat) if grp.name != "angle" else np.array([theta]),
        ), None
    from scipy.spatial.transform import Rotation

    mat = Rotation.from_quat(q / norm).as_matrix()[None]
    return (p[:3].copy(), grp.from_matrices(mat)), None


def twist_to_state(grp, dim, linear, angular):
    lin = np.asarray(linear, dtype=float)
    ang = np.asarray(angular, dtype=float)
    reason = _bad_numbers(np.concatenate([lin, ang]))
    if reason:
        return None, reason
    if dim == 2:
        if abs(lin[2]) > ROTATION_TOL or abs(ang[0]) > ROTATION_TOL or abs(ang[1]) > ROTATION_TOL:
            return None, "not a planar velocity"
        skew = np.array([[[0.0, -ang[2]], [ang[2], 0.0]]])
        return (lin[:2].copy(), grp.algebra_from_skew(skew)), None
    x, y, z = ang
    skew = np.array([[[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]]])
    return (lin[:3].copy(), grp.algebra_from_skew(skew)), None


def array_to_state(msg, dim, rot_check=True):
    """Float64MultiArray pose/twist -> ((t, vector, matrix), None) or (None, reason)."""
    data = np.asarray(msg.data, dtype=float)
    if len(data) != 1 + dim + dim * dim or len(msg.layout.dim) != 3 or msg.layout.data_offset != 0:
        return None, "malformed layout"
    reason = _bad_numbers(data)
    if reason:
        return None, reason
    mat = data[1 + dim :].reshape(dim, dim)
    if rot_check:
        if orthogonality(mat) > ROTATION_TOL or np.linalg.det(mat) < 0:
            return None, "rotation not in SO(d)"
    elif np.max(np.abs(mat + mat.T)) > ROTATION_TOL * max(1.0, np.max(np.abs(mat))):
        return None, "angular velocity not skew"
    return (float(data[0]), data[1 : 1 + dim].copy(), mat), None


@dataclass
class Received:
    """A decoded pose or twist: stamp (s and integer ns key), vector, rotation or algebra row."""

    t: float
    key: int
    vec: np.ndarray
    rot: np.ndarray


def _header_time(msg, frame_id, t_max):
    if frame_id is not None and msg.header.frame_id != frame_id:
        return None, f"unknown frame {msg.header.frame_id!r}"
    sec, nsec = msg.header.stamp.sec, msg.header.stamp.nanosec
    if nsec >= 1_000_000_000:
        return None, "malformed header"
    reason = _bad_stamp(sec + 1e-9 * nsec, t_max)
    return (None, reason) if reason else ((sec + 1e-9 * nsec, time_key(sec, nsec)), None)


def _array_time(t, t_max):
    reason = _bad_stamp(t, t_max)
    return (None, reason) if reason else ((t, int(round(t * 1e9))), None)


def decode_pose_msg(msg, grp, dim, frame_id=None, t_max=None):
    """PoseStamped (d <= 3) or Float64MultiArray (d >= 4) -> (Received, None) or (None, reason).

    ``frame_id`` (d <= 3): a pose in any other frame is refused; ``t_max``: stamps must lie in
    [0, t_max].
    """
    if dim <= 3:
        p, q = msg.pose.position, msg.pose.orientation
        val, reason = pose_to_state(grp, dim, (p.x, p.y, p.z), (q.x, q.y, q.z, q.w))
        if val is None:                 # the contents first: a corrupt message is named as such
            return None, reason
        stamp, reason = _header_time(msg, frame_id, t_max)
        return (None, reason) if stamp is None else (Received(*stamp, val[0], val[1]), None)
    res, reason = array_to_state(msg, dim)
    if res is None:
        return None, reason
    t, x, mat = res
    stamp, reason = _array_time(t, t_max)
    return (
        (None, reason)
        if stamp is None
        else (Received(*stamp, x, grp.from_matrices(mat[None])), None)
    )


def decode_twist_msg(msg, grp, dim, frame_id=None, t_max=None):
    """TwistStamped (d <= 3) or Float64MultiArray (d >= 4) -> (Received, None) | (None, reason)."""
    if dim <= 3:
        lin, ang = msg.twist.linear, msg.twist.angular
        val, reason = twist_to_state(grp, dim, (lin.x, lin.y, lin.z), (ang.x, ang.y, ang.z))
        if val is None:
            return None, reason
        stamp, reason = _header_time(msg, frame_id, t_max)
        return (None, reason) if stamp is None else (Received(*stamp, val[0], val[1]), None)
    res, reason = array_to_state(msg, dim, rot_check=False)
    if res is None:
        return None, reason
    t, v, skew = res
    stamp, reason = _array_time(t, t_max)
    return (
        (None, reason)
        if stamp is None
        else (Received(*stamp, v, grp.algebra_from_skew(skew[None])), None)
    )
