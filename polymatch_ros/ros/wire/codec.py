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
``stages/block_<b>`` lockstep with K agents per process: the rows of agents bK .. bK + K - 1
                     that one process hosts, in one message per round: data = [format 3, run id,
                     b, step, stage, flags, t, mask] then per row the agent index and its
                     fields as above (one mask for all rows).

Every decoder returns ``(value, None)`` or ``(None, reason)``, never raises: a value is finite,
within MAX_ABS, stamped inside the run, its rotation in SO(d) (Lemma 2.1: the flow keeps O_i
orthogonal); agents and the monitor drop and count a message with a reason, never use it.
"""

from __future__ import annotations

import array
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from ...core.so import RotationGroup

#: a stage message's header as read: (step, stage, flags, t, field mask)
Header = tuple[int, int, int, float, int]

STAGE_FORMAT = 2
BLOCK_FORMAT = 3
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


def stamp_of(t: float) -> tuple[int, int]:
    """Simulated time (s) -> (sec, nanosec) for builtin_interfaces/Time."""
    ns = int(round(t * 1e9))
    return ns // 1_000_000_000, ns % 1_000_000_000


def time_key(sec: int, nanosec: int) -> int:
    return int(sec) * 1_000_000_000 + int(nanosec)


def rot_values(grp: RotationGroup, g: np.ndarray) -> list[float]:
    """One rotation (a one-row group array) -> the list of floats the stage message carries."""
    if grp.name == "angle":
        return [float(g[0])]
    return grp.to_matrices(g)[0].ravel().tolist()


def rot_matrix_values(grp: RotationGroup, g: np.ndarray) -> list[float]:
    """One rotation (a one-row group array) -> its d x d matrix, row-major, as floats; in 2-D
    straight from the angle (a tenth of the cost of building the matrix array: one agent's
    exchange message each step)."""
    if grp.name == "angle":
        c, s = math.cos(g[0]), math.sin(g[0])
        return [c, -s, s, c]
    return grp.to_matrices(g)[0].ravel().tolist()


def rot_size(grp: RotationGroup) -> int:
    return 1 if grp.name == "angle" else grp.dim * grp.dim


def rot_from_values(grp: RotationGroup, values: Sequence[float] | np.ndarray) -> np.ndarray:
    if grp.name == "angle":
        return np.array([values[0]], dtype=float)
    d = grp.dim
    return grp.from_matrices(np.asarray(values, dtype=float).reshape(1, d, d))


def orthogonality(mat: np.ndarray) -> float:
    """max |O^T O - I| over the entries of one d x d matrix, or of a stack of them."""
    return float(np.max(np.abs(np.swapaxes(mat, -1, -2) @ mat - np.eye(mat.shape[-1]))))


def bad_rotation(mat: np.ndarray) -> str | None:
    """The reason a d x d matrix on the wire (or one of a stack of them) is no rotation in
    SO(d), or None."""
    if orthogonality(mat) > ROTATION_TOL or np.any(np.linalg.det(mat) < 0):
        return "rotation not in SO(d)"
    return None


def bad_skew(mat: np.ndarray) -> str | None:
    """The reason a d x d matrix on the wire (or one of a stack of them, each against its own
    scale) is no angular velocity (skew), or None."""
    asym = np.max(np.abs(mat + np.swapaxes(mat, -1, -2)), axis=(-2, -1))
    if np.any(asym > ROTATION_TOL * np.maximum(1.0, np.max(np.abs(mat), axis=(-2, -1)))):
        return "angular velocity not skew"
    return None


def _bad_numbers(values: np.ndarray) -> str | None:
    """The reason a vector of numbers is unusable, or None (one reduction: a NaN or an
    infinity makes the largest magnitude non-finite)."""
    if not values.size:
        return None
    largest = float(np.max(np.abs(values)))
    if not math.isfinite(largest):
        return "non-finite value"
    return "value out of range" if largest > MAX_ABS else None


def bad_scalars(values: Sequence[float]) -> str | None:
    """``_bad_numbers`` of a few Python floats (a geometry message's fields), without numpy."""
    if not all(map(math.isfinite, values)):
        return "non-finite value"
    if values and max(map(abs, values)) > MAX_ABS:
        return "value out of range"
    return None


def _bad_stamp(t: float, t_max: float | None) -> str | None:
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
    x: np.ndarray | None = None
    v: np.ndarray | None = None
    rot: np.ndarray | None = None  # one-row group array


@dataclass
class StageRows:
    """A decoded stage message of one agent or a block: the rows of ``agents`` for one round
    (step, stage), ``rot`` a group array of their rotations, ``x`` and ``v`` (n, d) where
    the message carries them."""

    agents: np.ndarray
    step: int
    stage: int
    flags: int
    t: float
    rot: np.ndarray
    x: np.ndarray | None = None
    v: np.ndarray | None = None

    @classmethod
    def of(cls, s: Stage) -> StageRows:
        """One agent's stage as a single row."""
        assert s.rot is not None  # every stage message carries the rotation
        return cls(np.array([s.agent]), s.step, s.stage, s.flags, s.t, s.rot,
                   None if s.x is None else s.x[None], None if s.v is None else s.v[None])

    def select(self, grp: RotationGroup, keep: np.ndarray) -> StageRows:
        """The rows where the boolean ``keep`` is true."""
        idx = np.flatnonzero(keep)
        return StageRows(self.agents[idx], self.step, self.stage, self.flags, self.t,
                         grp.take(self.rot, idx), None if self.x is None else self.x[idx],
                         None if self.v is None else self.v[idx])


def encode_stage(msg: Any, run_id: int, agent: int, step: int, stage: int, flags: int, t: float,
                 fields: Mapping[str, Sequence[float]], fmt: int = STAGE_FORMAT,
                 order: Sequence[tuple[str, int]] = FIELDS) -> Any:
    """Fill a Float64MultiArray with a stage: fields is a dict label -> values (x, v, rot);
    ``fmt`` and ``order`` (labels and mask bits): another message of the stage layout."""
    mask = 0
    body: list[float] = []
    for label, bit in order:
        if label in fields:
            mask |= bit
            body.extend(fields[label])
    # an array.array is taken as it is; a list would be type- and range-checked item by item
    msg.data = array.array("d", [
        float(fmt),
        float(run_id),
        float(agent),
        float(step),
        float(stage),
        float(flags),
        float(t),
        float(mask),
    ] + body)
    return msg


def _stage_header(
    data: np.ndarray, run_id: int, agent: int, t_max: float | None, fmt: int = STAGE_FORMAT
) -> tuple[Header | None, str | None]:
    """(step, stage, flags, t, mask) of a stage message's header, or the reason it is refused.

    ``agent`` is the sender's agent index (a block message: its block index)."""
    head = data[:HEADER].tolist()  # eight Python floats: cheaper to check than numpy's
    counts = head[:6] + head[7:]  # every field but the time is a non-negative integer
    if (
        any(v % 1.0 for v in counts)  # a fraction (or NaN, for a non-finite value)
        or min(counts[1:]) < 0
        or max(map(abs, head)) > 2.0**53
    ):
        return None, "malformed header"
    if int(head[0]) != fmt:
        return None, "unknown format"
    if int(head[1]) != int(run_id):
        return None, "unknown sender (run id)"
    if int(head[2]) != agent:
        return None, "unknown sender (agent index)"
    reason = _bad_stamp(float(head[6]), t_max)
    if reason:
        return None, reason
    return (int(head[3]), int(head[4]), int(head[5]), float(head[6]), int(head[7])), None


def stage_data(
    msg: Any, run_id: int, sender: int, t_max: float | None, fmt: int
) -> tuple[np.ndarray | None, Header | None, str | None]:
    """(data, header, None) of a stage or block message, or (None, None, reason)."""
    data = np.frombuffer(msg.data, dtype=float) if len(msg.data) else np.zeros(0)
    if len(data) < HEADER or msg.layout.dim or msg.layout.data_offset != 0:
        return None, None, "malformed layout"
    reason = _bad_numbers(data)
    if reason:
        return None, None, reason
    head, reason = _stage_header(data, run_id, sender, t_max, fmt)
    return data, head, reason


def decode_stage(msg: Any, grp: RotationGroup, dim: int, run_id: int, agent: int,
                 rot_tol: float = ROTATION_TOL,
                 t_max: float | None = None) -> tuple[Stage | None, str | None]:
    """Float64MultiArray -> (Stage, None) or (None, reason)."""
    data, head, reason = stage_data(msg, run_id, agent, t_max, STAGE_FORMAT)
    if data is None or head is None:
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


def encode_block(msg: Any, run_id: int, block: int, step: int, stage: int, flags: int, t: float,
                 agents: Sequence[int], fields: Mapping[str, np.ndarray]) -> Any:
    """Fill a Float64MultiArray with the stage rows of several agents of one block.

    ``fields``: label -> array of shape (len(agents), width), in ``FIELDS`` order."""
    mask = 0
    columns = [np.asarray(agents, dtype=float)[:, None]]
    for label, bit in FIELDS:
        if label in fields:
            mask |= bit
            columns.append(np.asarray(fields[label], dtype=float).reshape(len(agents), -1))
    head = np.array([BLOCK_FORMAT, run_id, block, step, stage, flags, t, mask], dtype=float)
    msg.data = array.array("d", np.concatenate([head, np.hstack(columns).ravel()]).tobytes())
    return msg


def block_members(agents: np.ndarray, block: int, k: int) -> bool:
    """A block message's agent column names agents of block ``block`` (bK .. bK + K - 1),
    each once."""
    first = block * k
    return bool(
        len(agents) <= k
        and np.all(agents == np.round(agents))
        and np.all(agents >= first)
        and np.all(agents < first + k)
        and len(np.unique(agents)) == len(agents)
    )


def block_rows(
    data: np.ndarray, block: int, k: int, mask: int, sizes: Mapping[str, int],
    order: Sequence[tuple[str, int]], mask_ok: bool,
) -> tuple[np.ndarray, dict[str, np.ndarray]] | tuple[None, str]:
    """The rows of a block message (stages or states) as (agent indices, {label: values}) for
    the fields of ``order`` that ``mask`` names, each ``sizes[label]`` wide, or (None, reason);
    ``mask_ok``: the mask is one the message kind allows."""
    width = 1 + sum(sizes[f] for f, bit in order if mask & bit)
    body = data[HEADER:]
    if not mask_ok or not body.size or body.size % width:
        return None, "malformed layout"
    rows = body.reshape(-1, width)
    if not block_members(rows[:, 0], block, k):
        return None, "unknown sender (agent index)"
    out: dict[str, np.ndarray] = {}
    pos = 1
    for label, bit in order:
        if mask & bit:
            out[label] = rows[:, pos : pos + sizes[label]]
            pos += sizes[label]
    return rows[:, 0].astype(int), out


def decode_block(msg: Any, grp: RotationGroup, dim: int, run_id: int, block: int, k: int,
                 rot_tol: float = ROTATION_TOL,
                 t_max: float | None = None) -> tuple[StageRows | None, str | None]:
    """Float64MultiArray of a block -> (StageRows, None) or (None, reason).

    Checked as ``decode_stage`` checks one agent's message, each row's rotation included;
    every agent index must lie in the block (bK .. bK + K - 1) and appear once.  The rows
    stay arrays (one rotation conversion for all): a packed lockstep process takes one such
    message per peer block and round, and per-row objects cost more than the rest of its
    receive path (py-spy, 1024 agents in 4 processes)."""
    data, head, reason = stage_data(msg, run_id, block, t_max, BLOCK_FORMAT)
    if data is None or head is None:
        return None, reason
    step, stage, flags, t, mask = head
    sizes = {"x": dim, "v": dim, "rot": rot_size(grp)}
    rows = block_rows(data, block, k, mask, sizes, FIELDS, not (mask & ~7 or not mask & 4))
    if rows[0] is None:
        return None, rows[1]
    agents, fields = rows
    values = fields["rot"]
    if grp.name == "angle":
        rot = values[:, 0].copy()
    else:
        mats = values.reshape(-1, grp.dim, grp.dim)
        if orthogonality(mats) > rot_tol:
            return None, "rotation not orthogonal"
        rot = grp.from_matrices(mats)
    x, v = fields.get("x"), fields.get("v")
    return StageRows(agents, step, stage, flags, t, rot,
                     None if x is None else x.copy(), None if v is None else v.copy()), None
