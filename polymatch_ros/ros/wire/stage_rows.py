"""Lockstep stage rows on the wire (``polymatch_interfaces/msg/StageRows``), and the checks
every decoder of the run's messages shares.

``agent_<i>/stage``   one agent's row of a stage: what the integrator's stage (step, stage)
                      needs of it (centroid, velocity, rotation), in the core's own
                      representation (an angle in 2-D where the scene integrates angles, else
                      the d x d matrix), so the distributed run computes with exactly the
                      numbers the centralised one does.
``stages/block_<b>``  lockstep with K agents per process: the rows of the agents bK .. bK + K - 1
                      that one process hosts, in one message a round.

The fields, their units and shapes are documented in the ``.msg`` file.  Every decoder
returns ``(value, None)`` or ``(None, reason)``, never raises: a value is of this run
(``run_id``) and of the topic's sender, finite, within MAX_ABS, stamped inside the run, its
arrays of the declared shapes, its rotations in SO(d) (Lemma 2.1: the flow keeps O_i
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

FLAG_STOP = 1
FIELDS = ("x", "v", "rot")  # a stage's fields, in the message's order

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


def floats(values: Any) -> array.array:
    """Numbers -> the ``array.array('d')`` a float64[] field takes as it is (a list or a numpy
    array would be type- and range-checked item by item on every publish)."""
    return array.array("d", np.ascontiguousarray(values, dtype=float).tobytes())


def indices(values: Any) -> array.array:
    """Agent indices -> the ``array.array('I')`` a uint32[] field takes as it is."""
    return array.array("I", np.ascontiguousarray(values, dtype=np.uint32).tobytes())


def numbers(field: Any) -> np.ndarray:
    """A float64[] field as a numpy view (no copy)."""
    return np.frombuffer(field, dtype=float) if len(field) else np.zeros(0)


def rot_values(grp: RotationGroup, g: np.ndarray) -> list[float]:
    """One rotation (a one-row group array) -> the floats the stage message carries."""
    if grp.name == "angle":
        return [float(g[0])]
    return grp.to_matrices(g)[0].ravel().tolist()


def rot_matrix_values(grp: RotationGroup, g: np.ndarray) -> list[float]:
    """One rotation (a one-row group array) -> its d x d matrix, row-major, as floats; in 2-D
    straight from the angle (a tenth of the cost of building the matrix array: one agent's
    state message each step)."""
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


def bad_numbers(values: np.ndarray) -> str | None:
    """The reason a vector of numbers is unusable, or None (one reduction: a NaN or an
    infinity makes the largest magnitude non-finite)."""
    if not values.size:
        return None
    largest = float(np.max(np.abs(values)))
    if not math.isfinite(largest):
        return "non-finite value"
    return "value out of range" if largest > MAX_ABS else None


def bad_scalars(values: Sequence[float]) -> str | None:
    """``bad_numbers`` of a few Python floats (a geometry message's fields), without numpy."""
    if not all(map(math.isfinite, values)):
        return "non-finite value"
    if values and max(map(abs, values)) > MAX_ABS:
        return "value out of range"
    return None


def bad_stamp(t: float, t_max: float | None) -> str | None:
    if not math.isfinite(t) or t < 0.0 or (t_max is not None and t > t_max + STAMP_SLACK):
        return "stamp outside the run"
    return None


def header_time(msg: Any, t_max: float | None) -> tuple[tuple[float, int] | None, str | None]:
    """(simulated time s, its integer ns key) of a message's ``std_msgs/Header`` stamp, or the
    reason it is refused."""
    sec, nsec = msg.header.stamp.sec, msg.header.stamp.nanosec
    if nsec >= 1_000_000_000:
        return None, "malformed header"
    t = sec + 1e-9 * nsec
    reason = bad_stamp(t, t_max)
    return (None, reason) if reason else ((t, time_key(sec, nsec)), None)


def block_members(agents: np.ndarray, block: int, k: int) -> bool:
    """A block message's agents are agents of block ``block`` (bK .. bK + K - 1), each once."""
    first = block * k
    return bool(
        len(agents) <= k
        and np.all(agents >= first)
        and np.all(agents < first + k)
        and len(np.unique(agents)) == len(agents)
    )


def shaped(fields: Mapping[str, Any], widths: Mapping[str, int], n: int,
           optional: Sequence[str] = ()) -> tuple[dict[str, np.ndarray] | None, str | None]:
    """The float64[] ``fields`` as (n, width) arrays (views), checked: each of n rows of its
    width (an ``optional`` field may be empty), every number finite and within MAX_ABS; or
    (None, reason)."""
    out: dict[str, np.ndarray] = {}
    for label, field in fields.items():
        values = numbers(field)
        if not values.size and label in optional:
            continue
        if n == 0 or values.size != n * widths[label]:
            return None, "malformed layout"
        reason = bad_numbers(values)
        if reason:
            return None, reason
        out[label] = values.reshape(n, widths[label])
    return out, None


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
    the message carries them.  ``flags``: FLAG_STOP, with the agreed stop step (graphs) in the
    bits above it."""

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


_EMPTY = array.array("d")


def _fill_stage(msg: Any, run_id: int, sender: int, step: int, stage: int, flags: int,
                t: float, agents: Any, fields: Mapping[str, Any]) -> Any:
    msg.run_id, msg.sender, msg.step, msg.stage = int(run_id), int(sender), int(step), int(stage)
    msg.stop = bool(flags & FLAG_STOP)
    msg.stop_step = flags >> 1 if flags > FLAG_STOP else -1
    msg.t = float(t)
    msg.agents = indices(agents)
    msg.centroids = floats(fields["x"]) if "x" in fields else _EMPTY
    msg.velocities = floats(fields["v"]) if "v" in fields else _EMPTY
    msg.rotations = floats(fields["rot"])
    return msg


def encode_stage(msg: Any, run_id: int, agent: int, step: int, stage: int, flags: int, t: float,
                 fields: Mapping[str, Sequence[float]]) -> Any:
    """Fill a StageRows message with one agent's stage: ``fields`` label -> values (x, v, rot;
    rot always); ``flags`` FLAG_STOP, with the agreed stop step in the bits above it."""
    return _fill_stage(msg, run_id, agent, step, stage, flags, t, [agent], fields)


def encode_block(msg: Any, run_id: int, block: int, step: int, stage: int, flags: int, t: float,
                 agents: Sequence[int], fields: Mapping[str, np.ndarray]) -> Any:
    """Fill a StageRows message with the stage rows of several agents of one block.

    ``fields``: label -> array of shape (len(agents), width)."""
    return _fill_stage(msg, run_id, block, step, stage, flags, t, agents, fields)


def _flags(msg: Any) -> int:
    if not msg.stop:
        return 0
    return FLAG_STOP | (msg.stop_step << 1 if msg.stop_step >= 0 else 0)


def _stage_rows(msg: Any, grp: RotationGroup, dim: int, run_id: int, sender: int,
                rot_tol: float, t_max: float | None,
                members: Any) -> tuple[StageRows | None, str | None]:
    """A StageRows message -> (StageRows, None) or (None, reason); ``members(agents)``: the
    agents are the ones the sender may send."""
    if msg.run_id != run_id:
        return None, "unknown sender (run id)"
    if msg.sender != sender:
        return None, "unknown sender (agent index)"
    reason = bad_stamp(msg.t, t_max)
    if reason:
        return None, reason
    agents = np.frombuffer(msg.agents, dtype=np.uint32).astype(int) if len(msg.agents) \
        else np.zeros(0, dtype=int)
    if not len(agents):
        return None, "malformed layout"
    if not members(agents):
        return None, "unknown sender (agent index)"
    widths = {"x": dim, "v": dim, "rot": rot_size(grp)}
    rows, reason = shaped({"x": msg.centroids, "v": msg.velocities, "rot": msg.rotations},
                          widths, len(agents), optional=("x", "v"))
    if rows is None:
        return None, reason
    values = rows["rot"]
    if grp.name == "angle":
        rot = values[:, 0].copy()
    else:
        mats = values.reshape(-1, grp.dim, grp.dim)
        if orthogonality(mats) > rot_tol:
            return None, "rotation not orthogonal"
        if np.any(np.linalg.det(mats) < 0):     # orthogonal, but a reflection: not in SO(d)
            return None, "rotation not in SO(d)"
        rot = grp.from_matrices(mats)
    x, v = rows.get("x"), rows.get("v")
    return StageRows(agents, int(msg.step), int(msg.stage), _flags(msg), float(msg.t), rot,
                     None if x is None else x.copy(), None if v is None else v.copy()), None


def decode_agent_rows(msg: Any, grp: RotationGroup, dim: int, run_id: int, agent: int,
                      rot_tol: float = ROTATION_TOL,
                      t_max: float | None = None) -> tuple[StageRows | None, str | None]:
    """One agent's StageRows message -> (its single row, None) or (None, reason): what a
    lockstep process of one agent takes from each peer."""
    return _stage_rows(msg, grp, dim, run_id, agent, rot_tol, t_max,
                       lambda agents: len(agents) == 1 and agents[0] == agent)


def decode_stage(msg: Any, grp: RotationGroup, dim: int, run_id: int, agent: int,
                 rot_tol: float = ROTATION_TOL,
                 t_max: float | None = None) -> tuple[Stage | None, str | None]:
    """One agent's StageRows message -> (Stage, None) or (None, reason)."""
    rows, reason = decode_agent_rows(msg, grp, dim, run_id, agent, rot_tol, t_max)
    if rows is None:
        return None, reason
    return Stage(agent, rows.step, rows.stage, rows.flags, rows.t,
                 None if rows.x is None else rows.x[0], None if rows.v is None else rows.v[0],
                 grp.take(rows.rot, [0])), None


def decode_block(msg: Any, grp: RotationGroup, dim: int, run_id: int, block: int, k: int,
                 rot_tol: float = ROTATION_TOL,
                 t_max: float | None = None) -> tuple[StageRows | None, str | None]:
    """A block's StageRows message -> (StageRows, None) or (None, reason).

    Checked as ``decode_stage`` checks one agent's message, each row's rotation included;
    every agent must lie in the block (bK .. bK + K - 1) and appear once.  The rows stay arrays
    (one rotation conversion for all): a packed lockstep process takes one such message per
    peer block and round, and per-row objects would cost more than the rest of its receive
    path."""
    return _stage_rows(msg, grp, dim, run_id, block, rot_tol, t_max,
                       lambda agents: block_members(agents, block, k))
