"""The run's own exchange of states: what peers and the monitor read, pinned to the run.

``agent_<i>/pose`` is for people and tools (``ros2 topic echo``, RViz, a recording): anything
on the ROS graph may publish there, and a reader cannot tell its writers apart (rclpy's
message info carries no publisher id).  The agents of a run therefore also publish each
state on ``agent_<i>/exchange``, stamped with the run's id, and their peers (realtime,
bridge) and the monitor read only that: a message of another run, of a stale process of an
earlier run or of any other writer without the id is dropped and counted with its reason
(``unknown sender (run id)``), never used.  A restarted agent process gets its run's id
again, so its peers take it back.

``agent_<i>/exchange``  ``std_msgs/Float64MultiArray``, no layout dims: data = [format 4,
                        run id, agent, 0, 0, 0, t, mask] then x (d) if mask & 1, v (d) if
                        mask & 2, the rotation O_i as a row-major d x d matrix (mask & 4,
                        always), W_i as a row-major d x d skew matrix (mask & 8, with v:
                        second order).  x is the centroid relative to the scene's origin, the
                        number the core computes with.
``exchanges/block_<b>`` lockstep with K > 1 agents per process: the states of the agents of
                        block b (bK .. bK + K - 1) that one process hosts, in one message per
                        step: data = [format 5, run id, b, 0, 0, 0, t, mask] then per row the
                        agent index and its fields as above (one mask for all rows).  The
                        monitor then takes P messages a step instead of N: at 1024 agents in 4
                        processes the per-agent messages kept it at a full core and took a
                        third of every agent process's time.  Final states stay per agent.

Unlike the stage messages (between agents that all compute in one representation), the
exchange is read by nodes that may not share the agents' representation: a projection
integrator computes with matrices in 2-D where the monitor and the runner keep angles
(``core.simulate.prepare``).  So the rotation goes as the matrix, whatever the sender's
representation, and each reader converts it to its own (``from_matrices``; in 2-D the angle
comes back as atan2 of the matrix entries, to an ulp and within (-pi, pi]).
"""

from __future__ import annotations

import array
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from .codec import (
    HEADER,
    bad_rotation,
    bad_skew,
    block_rows,
    encode_stage,
    rot_matrix_values,
    stage_data,
)

if TYPE_CHECKING:
    from ...core.so import RotationGroup

EXCHANGE_FORMAT = 4
EXCHANGE_BLOCK_FORMAT = 5
#: field, bit in the header's mask, in wire order: the stage fields and W_i
EXCHANGE_FIELDS = (("x", 1), ("v", 2), ("rot", 4), ("w", 8))


@dataclass
class Motion:
    """One agent's state as exchanged: simulated time (s, and its integer ns key), centroid
    offset x, rotation (a one-row group array), and in second order v and W_i (an algebra
    row)."""

    t: float
    key: int
    x: np.ndarray
    rot: np.ndarray
    v: np.ndarray | None = None
    w: np.ndarray | None = None


def encode_exchange(msg: Any, grp: RotationGroup, run_id: int, agent: int, t: float,
                    x: np.ndarray, rot_one: np.ndarray, v: np.ndarray | None = None,
                    w_one: np.ndarray | None = None) -> Any:
    """Fill a Float64MultiArray with one agent's state (``w_one``: its W_i as an algebra row,
    given with ``v``)."""
    fields: dict[str, Sequence[float]] = {"x": np.asarray(x, dtype=float).tolist(),
                                          "rot": rot_matrix_values(grp, rot_one)}
    if v is not None and w_one is not None:
        fields["v"] = np.asarray(v, dtype=float).tolist()
        fields["w"] = grp.algebra_to_skew(w_one)[0].ravel().tolist()
    return encode_stage(msg, run_id, agent, 0, 0, 0, t, fields, fmt=EXCHANGE_FORMAT,
                        order=EXCHANGE_FIELDS)


def decode_exchange(msg: Any, grp: RotationGroup, dim: int, run_id: int, agent: int,
                    t_max: float | None = None) -> tuple[Motion | None, str | None]:
    """Float64MultiArray -> (Motion, None) or (None, reason): the header as a stage message's
    (format, this run's id, this agent, a stamp inside the run), the rotation in SO(d), W_i
    skew."""
    data, head, reason = stage_data(msg, run_id, agent, t_max, EXCHANGE_FORMAT)
    if data is None or head is None:
        return None, reason
    t, mask = head[3], head[4]
    sizes = {"x": dim, "v": dim, "rot": dim * dim, "w": dim * dim}
    if (mask & ~15 or mask & 5 != 5 or bool(mask & 2) != bool(mask & 8)
            or len(data) != HEADER + sum(sizes[f] for f, bit in EXCHANGE_FIELDS if mask & bit)):
        return None, "malformed layout"
    values: dict[str, np.ndarray] = {}
    pos = HEADER
    for label, bit in EXCHANGE_FIELDS:
        if mask & bit:
            values[label] = data[pos:pos + sizes[label]].copy()
            pos += sizes[label]
    rot = values["rot"].reshape(1, dim, dim)
    reason = bad_rotation(rot[0])
    if "w" in values:
        reason = reason or bad_skew(values["w"].reshape(dim, dim))
    if reason:
        return None, reason
    out = Motion(t, int(round(t * 1e9)), values["x"], grp.from_matrices(rot))
    if "w" in values:
        out.v, out.w = values["v"], grp.algebra_from_skew(values["w"].reshape(1, dim, dim))
    return out, None


def encode_exchange_block(msg: Any, grp: RotationGroup, run_id: int, block: int, t: float,
                          agents: Sequence[int], x: np.ndarray, rot: np.ndarray,
                          v: np.ndarray | None = None, w: np.ndarray | None = None) -> Any:
    """Fill a Float64MultiArray with the states of several agents of one block: ``x`` (n, d),
    ``rot`` a group array of n rows, in second order ``v`` (n, d) and ``w`` an algebra array."""
    n = len(agents)
    columns = [np.asarray(agents, dtype=float)[:, None], np.asarray(x, dtype=float)]
    mask = 1 | 4
    mats = grp.to_matrices(rot).reshape(n, -1)
    if v is not None and w is not None:  # second order: x, v, O_i, W_i (EXCHANGE_FIELDS)
        mask |= 2 | 8
        columns += [np.asarray(v, dtype=float), mats, grp.algebra_to_skew(w).reshape(n, -1)]
    else:
        columns.append(mats)
    head = np.array([EXCHANGE_BLOCK_FORMAT, run_id, block, 0, 0, 0, t, mask], dtype=float)
    msg.data = array.array("d", np.concatenate([head, np.hstack(columns).ravel()]).tobytes())
    return msg


def decode_exchange_block(
    msg: Any, grp: RotationGroup, dim: int, run_id: int, block: int, k: int,
    t_max: float | None = None,
) -> tuple[list[tuple[int, Motion]] | None, str | None]:
    """Float64MultiArray of a block -> ([(agent, Motion), ...], None) or (None, reason).

    Checked as ``decode_exchange`` checks one agent's message, every row at once: one row
    that is not this run's block member, or not in SO(d) (Lemma 2.1), or whose W_i is not
    skew drops the whole message."""
    data, head, reason = stage_data(msg, run_id, block, t_max, EXCHANGE_BLOCK_FORMAT)
    if data is None or head is None:
        return None, reason
    t, mask = head[3], head[4]
    sizes = {"x": dim, "v": dim, "rot": dim * dim, "w": dim * dim}
    valid = not (mask & ~15 or mask & 5 != 5 or bool(mask & 2) != bool(mask & 8))
    rows = block_rows(data, block, k, mask, sizes, EXCHANGE_FIELDS, valid)
    if rows[0] is None:
        return None, rows[1]
    agents, fields = rows
    values = {label: v.copy() for label, v in fields.items()}
    n = len(agents)
    mats = values["rot"].reshape(n, dim, dim)
    skews = values["w"].reshape(n, dim, dim) if "w" in values else None
    reason = bad_rotation(mats) or (None if skews is None else bad_skew(skews))
    if reason:
        return None, reason
    rot, key = grp.from_matrices(mats), int(round(t * 1e9))
    w = None if skews is None else grp.algebra_from_skew(skews)
    out = []
    for r, a in enumerate(agents.tolist()):
        motion = Motion(t, key, values["x"][r], grp.take(rot, [r]))
        if w is not None:
            motion.v, motion.w = values["v"][r], grp.algebra_take(w, [r])
        out.append((a, motion))
    return out, None
