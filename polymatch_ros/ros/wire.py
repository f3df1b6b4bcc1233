"""Messages on the wire: poses, velocities and lockstep stages, with validation.

Topics (ensemble namespace ``/<ns>``, default ``/polymatch``):

``/<ns>/agent_<i>/pose``   d <= 3: ``geometry_msgs/PoseStamped``: position = centroid (z = 0 in
                           2-D), orientation = quaternion of O_i (about z in 2-D), header.stamp =
                           simulated time, header.frame_id = frame (default ``world``).
                           d >= 4: ``std_msgs/Float64MultiArray`` with layout dims
                           [("t", 1), ("centroid", d), ("rotation_row_major", d*d)].
``/<ns>/agent_<i>/twist``  second order only.  d <= 3: ``geometry_msgs/TwistStamped`` (linear =
                           centroid velocity, angular = spatial angular velocity, i.e. vee(W_i)).
                           d >= 4: Float64MultiArray dims [("t", 1), ("velocity", d),
                           ("angular_row_major", d*d)].
``/<ns>/agent_<i>/stage``  lockstep only: ``std_msgs/Float64MultiArray``, no layout dims (they cost
                           a Python object each on every publish and take), data =
                           [format 2, run id, agent, step, stage, flags, t, mask] then x (d) if
                           mask & 1, v (d) if mask & 2, rot (r) (mask & 4, always); rot is the
                           core's representation (angle in 2-D, row-major matrix otherwise), so the
                           distributed run computes with exactly the numbers the centralised one does.

Every decoder returns ``(value, None)`` or ``(None, reason)``; agents and the
monitor drop and count a message with a reason, never use it.
"""

import math
from dataclasses import dataclass

import numpy as np

STAGE_FORMAT = 2
HEADER = 8
FLAG_STOP = 1
FIELDS = (("x", 1), ("v", 2), ("rot", 4))     # field, bit in the header's field mask, in wire order
QUAT_TOL = 1e-6


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
    rot: np.ndarray = None      # one-row group array


def encode_stage(msg, run_id, agent, step, stage, flags, t, fields):
    """Fill a Float64MultiArray with a stage: fields is a dict label -> values (x, v, rot).

    No layout dimensions: nested messages cost a Python object per dimension on every
    publish and take; the header's mask says which fields follow, in FIELDS order.
    """
    mask = 0
    body = []
    for label, bit in FIELDS:
        if label in fields:
            mask |= bit
            body.extend(fields[label])
    msg.data = [float(STAGE_FORMAT), float(run_id), float(agent), float(step), float(stage), float(flags),
                float(t), float(mask)] + body
    return msg


def decode_stage(msg, grp, dim, run_id, agent, rot_tol):
    """Float64MultiArray -> (Stage, None) or (None, reason)."""
    data = np.frombuffer(msg.data, dtype=float) if len(msg.data) else np.zeros(0)
    if len(data) < HEADER or msg.layout.dim or msg.layout.data_offset != 0:
        return None, "malformed layout"
    if not np.all(np.isfinite(data)):
        return None, "non-finite value"
    if int(data[0]) != STAGE_FORMAT:
        return None, "unknown format"
    if int(data[1]) != int(run_id):
        return None, "unknown sender (run id)"
    if int(data[2]) != agent:
        return None, "unknown sender (agent index)"
    mask = int(data[7])
    sizes = {"x": dim, "v": dim, "rot": rot_size(grp)}
    if mask & ~7 or not mask & 4 or len(data) != HEADER + sum(sizes[f] for f, bit in FIELDS if mask & bit):
        return None, "malformed layout"
    out = Stage(agent, int(data[3]), int(data[4]), int(data[5]), float(data[6]))
    pos = HEADER
    for label, bit in FIELDS:
        if not mask & bit:
            continue
        values = data[pos:pos + sizes[label]]
        pos += sizes[label]
        if label == "rot":
            if grp.name != "angle" and orthogonality(values.reshape(grp.dim, grp.dim)) > rot_tol:
                return None, "rotation not orthogonal"
            out.rot = rot_from_values(grp, values)
        else:
            setattr(out, label, values.copy())
    return out, None


# -- poses ---------------------------------------------------------------------------------


def pose_fields(grp, x, g):
    """(position xyz, quaternion xyzw) of one agent for a PoseStamped (d <= 3)."""
    pos = np.zeros(3)
    pos[:len(x)] = x
    if grp.dim == 2:
        theta = float(grp.from_matrices(grp.to_matrices(g))[0]) if grp.name != "angle" else float(g[0])
        quat = np.array([0.0, 0.0, math.sin(theta / 2), math.cos(theta / 2)])
    else:
        from scipy.spatial.transform import Rotation
        quat = Rotation.from_matrix(grp.to_matrices(g)[0]).as_quat()
    return pos, quat


def pose_to_state(grp, dim, position, quat):
    """PoseStamped contents -> ((x, one-row rotation), None) or (None, reason)."""
    p = np.asarray(position, dtype=float)
    q = np.asarray(quat, dtype=float)
    if not (np.all(np.isfinite(p)) and np.all(np.isfinite(q))):
        return None, "non-finite value"
    norm = float(np.linalg.norm(q))
    if abs(norm - 1.0) > QUAT_TOL:
        return None, "quaternion far from unit norm"
    if dim == 2:
        if abs(p[2]) > 1e-9 or abs(q[0]) > QUAT_TOL or abs(q[1]) > QUAT_TOL:
            return None, "not a planar pose"
        theta = 2.0 * math.atan2(q[2], q[3])
        mat = np.array([[[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]]])
        return (p[:2].copy(), grp.from_matrices(mat) if grp.name != "angle" else np.array([theta])), None
    from scipy.spatial.transform import Rotation
    mat = Rotation.from_quat(q / norm).as_matrix()[None]
    return (p[:3].copy(), grp.from_matrices(mat)), None


def array_pose(dim_cls, msg_cls, t, x, mat, labels=("t", "centroid", "rotation_row_major")):
    msg = msg_cls()
    d = len(x)
    msg.layout.dim = [dim_cls(label=labels[0], size=1, stride=1),
                      dim_cls(label=labels[1], size=d, stride=d),
                      dim_cls(label=labels[2], size=d * d, stride=d * d)]
    msg.data = [float(t)] + [float(v) for v in x] + [float(v) for v in np.asarray(mat).ravel()]
    return msg


def array_to_state(msg, dim, rot_check=True):
    """Float64MultiArray pose/twist -> ((t, vector, matrix), None) or (None, reason)."""
    data = np.asarray(msg.data, dtype=float)
    if len(data) != 1 + dim + dim * dim or len(msg.layout.dim) != 3:
        return None, "malformed layout"
    if not np.all(np.isfinite(data)):
        return None, "non-finite value"
    mat = data[1 + dim:].reshape(dim, dim)
    if rot_check:
        if orthogonality(mat) > 1e-9 or np.linalg.det(mat) < 0:
            return None, "rotation not in SO(d)"
    elif np.max(np.abs(mat + mat.T)) > 1e-9 * max(1.0, np.max(np.abs(mat))):
        return None, "angular velocity not skew"
    return (float(data[0]), data[1:1 + dim].copy(), mat), None


def twist_fields(grp, v, w_row):
    """(linear xyz, angular xyz) of one agent's velocities for a TwistStamped (d <= 3)."""
    lin = np.zeros(3)
    lin[:len(v)] = v
    skew = grp.algebra_to_skew(w_row)[0]
    ang = np.array([skew[2, 1], skew[0, 2], skew[1, 0]]) if grp.dim == 3 else np.array([0.0, 0.0, skew[1, 0]])
    return lin, ang


def twist_to_state(grp, dim, linear, angular):
    lin = np.asarray(linear, dtype=float)
    ang = np.asarray(angular, dtype=float)
    if not (np.all(np.isfinite(lin)) and np.all(np.isfinite(ang))):
        return None, "non-finite value"
    if dim == 2:
        skew = np.array([[[0.0, -ang[2]], [ang[2], 0.0]]])
        return (lin[:2].copy(), grp.algebra_from_skew(skew)), None
    x, y, z = ang
    skew = np.array([[[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]]])
    return (lin[:3].copy(), grp.algebra_from_skew(skew)), None


@dataclass
class Received:
    """A decoded pose or twist: stamp (s and integer ns key), vector, rotation or algebra row."""
    t: float
    key: int
    vec: np.ndarray
    rot: np.ndarray


def decode_pose_msg(msg, grp, dim, frame_id=None):
    """PoseStamped (d <= 3) or Float64MultiArray (d >= 4) -> (Received, None) or (None, reason).

    ``frame_id`` (d <= 3): a pose in any other frame is refused.
    """
    if dim <= 3:
        if frame_id is not None and msg.header.frame_id != frame_id:
            return None, f"unknown frame {msg.header.frame_id!r}"
        p, q = msg.pose.position, msg.pose.orientation
        val, reason = pose_to_state(grp, dim, (p.x, p.y, p.z), (q.x, q.y, q.z, q.w))
        if val is None:
            return None, reason
        sec, nsec = msg.header.stamp.sec, msg.header.stamp.nanosec
        return Received(sec + 1e-9 * nsec, time_key(sec, nsec), val[0], val[1]), None
    res, reason = array_to_state(msg, dim)
    if res is None:
        return None, reason
    t, x, mat = res
    return Received(t, int(round(t * 1e9)), x, grp.from_matrices(mat[None])), None


def decode_twist_msg(msg, grp, dim):
    """TwistStamped (d <= 3) or Float64MultiArray (d >= 4) -> (Received, None) or (None, reason)."""
    if dim <= 3:
        lin, ang = msg.twist.linear, msg.twist.angular
        val, reason = twist_to_state(grp, dim, (lin.x, lin.y, lin.z), (ang.x, ang.y, ang.z))
        if val is None:
            return None, reason
        sec, nsec = msg.header.stamp.sec, msg.header.stamp.nanosec
        return Received(sec + 1e-9 * nsec, time_key(sec, nsec), val[0], val[1]), None
    res, reason = array_to_state(msg, dim, rot_check=False)
    if res is None:
        return None, reason
    t, v, skew = res
    return Received(t, int(round(t * 1e9)), v, grp.algebra_from_skew(skew[None])), None


# -- topic names and QoS ------------------------------------------------------------------


def agent_topic(ensemble, agent, kind):
    """/<ensemble>/agent_<i>/<kind> with kind in pose, twist, stage."""
    return f"/{ensemble.strip('/')}/agent_{agent}/{kind}"


def ensemble_topic(ensemble, name):
    return f"/{ensemble.strip('/')}/{name}"


def qos_profiles():
    """QoS used on each kind of topic (imported lazily: rclpy is only needed here)."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    return {
        # every lockstep stage must arrive.  VOLATILE: agents start only once their writers
        # have matched every expected reader (TRANSIENT_LOCAL halves the round rate here)
        "stage": QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=16, reliability=ReliabilityPolicy.RELIABLE,
                            durability=DurabilityPolicy.VOLATILE),
        # stage readers keep every sample: a flood on a peer's topic can then never evict the
        # peer's real message before it is taken (it only blocks the flooding writer)
        "stage_in": QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE,
                               durability=DurabilityPolicy.VOLATILE),
        # poses: the monitor must see every lockstep pose; echo and RViz match RELIABLE/VOLATILE
        "pose": QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100, reliability=ReliabilityPolicy.RELIABLE,
                           durability=DurabilityPolicy.VOLATILE),
        # realtime peers: only the newest pose matters; a deeper queue would feed stale poses.
        # BEST_EFFORT (as sensor data): a lost pose is replaced by the next one, whereas a
        # RELIABLE reader holds every later pose back until the lost one is repaired (seconds
        # on a loaded machine, where loopback UDP drops datagrams)
        "latest": QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.BEST_EFFORT,
                             durability=DurabilityPolicy.VOLATILE),
        # headline values: a late `ros2 topic echo` still gets the last one
        "latched": QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                              durability=DurabilityPolicy.TRANSIENT_LOCAL),
        # commands are not replayed to agents that join later (a restarted agent must not stop)
        "control": QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10, reliability=ReliabilityPolicy.RELIABLE,
                              durability=DurabilityPolicy.VOLATILE),
    }
