"""The run's own exchange of states: what peers and the monitor read, pinned to the run.

``agent_<i>/pose`` is for people and tools (``ros2 topic echo``, RViz, a recording): anything
on the ROS graph may publish there, and a reader cannot tell its writers apart (rclpy's
message info carries no publisher id).  The agents of a run therefore also publish each
state as a ``polymatch_interfaces/msg/AgentState`` on ``agent_<i>/state``, with the run's id,
and their peers (realtime, bridge) and the monitor read only that: a message of another run,
of a stale process of an earlier run, or of another writer is dropped and counted with its
reason (``unknown sender (run id)``), never used; a writer of another type never matches the
topic at all.  A restarted agent process gets its run's id again, so its peers take it back.

``states/block_<b>``  lockstep with K > 1 agents per process: ``AgentStateBlock``, the states
                      of the agents of block b (bK .. bK + K - 1) that one process hosts, in
                      one message per step (the monitor then takes P messages a step, not N).
                      Final states stay per agent.

Unlike the stage rows (between agents that all compute in one representation), the state is
read by nodes that may not share the agents' representation: a projection integrator computes
with matrices in 2-D where the monitor and the runner keep angles
(``core.stepping.simulate.prepare``).
So the rotation goes as the matrix, whatever the sender's representation, and each reader
converts it to its own (``from_matrices``; in 2-D the angle comes back as atan2 of the matrix
entries, to an ulp and within (-pi, pi]).  Fields, units and shapes: the ``.msg`` files.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from .stage_rows import (
    bad_numbers,
    bad_rotation,
    bad_skew,
    block_members,
    floats,
    header_time,
    indices,
    rot_matrix_values,
    shaped,
    stamp_of,
)

if TYPE_CHECKING:
    from ...core.so import RotationGroup

_OPTIONAL = ("v", "w")


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


def _stamp(msg: Any, t: float, frame_id: str) -> None:
    msg.header.stamp.sec, msg.header.stamp.nanosec = stamp_of(t)
    msg.header.frame_id = frame_id


def encode_exchange(msg: Any, grp: RotationGroup, run_id: int, agent: int, t: float,
                    x: np.ndarray, rot_one: np.ndarray, v: np.ndarray | None = None,
                    w_one: np.ndarray | None = None, frame_id: str = "world") -> Any:
    """Fill an AgentState with one agent's state (``w_one``: its W_i as an algebra row, given
    with ``v``)."""
    _stamp(msg, t, frame_id)
    msg.run_id, msg.agent = int(run_id), int(agent)
    msg.centroid = floats(x)
    msg.rotation = floats(rot_matrix_values(grp, rot_one))
    if v is not None and w_one is not None:
        msg.velocity, msg.angular_velocity = floats(v), floats(grp.algebra_to_skew(w_one)[0])
    else:
        msg.velocity = msg.angular_velocity = floats([])
    return msg


def _second_order_pair(rows: dict[str, np.ndarray]) -> str | None:
    return "malformed layout" if ("v" in rows) != ("w" in rows) else None


def _checked(msg: Any, fields: dict[str, Any], dim: int, n: int,
             t_max: float | None) -> tuple[tuple[float, int, dict[str, np.ndarray]] | None,
                                           str | None]:
    """The shared checks of a state or a block of them: stamp, shapes, numbers, SO(d) and skew
    -> ((t, key, {label: (n, width) rows}), None) or (None, reason)."""
    stamp, reason = header_time(msg, t_max)
    if stamp is None:
        return None, reason
    widths = {"x": dim, "v": dim, "rot": dim * dim, "w": dim * dim}
    rows, reason = shaped(fields, widths, n, optional=_OPTIONAL)
    if rows is None:
        return None, reason
    reason = _second_order_pair(rows) or bad_rotation(rows["rot"].reshape(n, dim, dim))
    if not reason and "w" in rows:
        reason = bad_skew(rows["w"].reshape(n, dim, dim))
    return (None, reason) if reason else ((stamp[0], stamp[1], rows), None)


def decode_exchange(msg: Any, grp: RotationGroup, dim: int, run_id: int, agent: int,
                    t_max: float | None = None) -> tuple[Motion | None, str | None]:
    """AgentState -> (Motion, None) or (None, reason): this run's id, this agent, a stamp
    inside the run, the shapes of dimension ``dim``, the rotation in SO(d), W_i skew."""
    if msg.run_id != run_id:
        return None, "unknown sender (run id)"
    if msg.agent != agent:
        return None, "unknown sender (agent index)"
    fields = {"x": msg.centroid, "v": msg.velocity, "rot": msg.rotation,
              "w": msg.angular_velocity}
    checked, reason = _checked(msg, fields, dim, 1, t_max)
    if checked is None:
        return None, reason
    t, key, rows = checked
    out = Motion(t, key, rows["x"][0].copy(), grp.from_matrices(rows["rot"].reshape(1, dim, dim)))
    if "w" in rows:
        out.v = rows["v"][0].copy()
        out.w = grp.algebra_from_skew(rows["w"].reshape(1, dim, dim))
    return out, None


def encode_exchange_block(msg: Any, grp: RotationGroup, run_id: int, block: int, t: float,
                          agents: Sequence[int], x: np.ndarray, rot: np.ndarray,
                          v: np.ndarray | None = None, w: np.ndarray | None = None,
                          frame_id: str = "world") -> Any:
    """Fill an AgentStateBlock with the states of several agents of one block: ``x`` (n, d),
    ``rot`` a group array of n rows, in second order ``v`` (n, d) and ``w`` an algebra array."""
    _stamp(msg, t, frame_id)
    msg.run_id, msg.block = int(run_id), int(block)
    msg.agents = indices(agents)
    msg.centroids = floats(x)
    msg.rotations = floats(grp.to_matrices(rot))
    if v is not None and w is not None:
        msg.velocities, msg.angular_velocities = floats(v), floats(grp.algebra_to_skew(w))
    else:
        msg.velocities = msg.angular_velocities = floats([])
    return msg


def decode_exchange_block(
    msg: Any, grp: RotationGroup, dim: int, run_id: int, block: int, k: int,
    t_max: float | None = None,
) -> tuple[list[tuple[int, Motion]] | None, str | None]:
    """AgentStateBlock -> ([(agent, Motion), ...], None) or (None, reason).

    Checked as ``decode_exchange`` checks one agent's message, every row at once: one row
    that is not this run's block member, or not in SO(d) (Lemma 2.1), or whose W_i is not
    skew drops the whole message."""
    if msg.run_id != run_id:
        return None, "unknown sender (run id)"
    agents = np.frombuffer(msg.agents, dtype=np.uint32).astype(int) if len(msg.agents) \
        else np.zeros(0, dtype=int)
    if msg.block != block or not block_members(agents, block, k):
        return None, "unknown sender (agent index)"
    n = len(agents)
    fields = {"x": msg.centroids, "v": msg.velocities, "rot": msg.rotations,
              "w": msg.angular_velocities}
    checked, reason = _checked(msg, fields, dim, n, t_max)
    if checked is None:
        return None, reason
    t, key, rows = checked
    rot = grp.from_matrices(rows["rot"].reshape(n, dim, dim))
    w = None if "w" not in rows else grp.algebra_from_skew(rows["w"].reshape(n, dim, dim))
    out = []
    for r, a in enumerate(agents.tolist()):
        motion = Motion(t, key, rows["x"][r].copy(), grp.take(rot, [r]))
        if w is not None:
            motion.v, motion.w = rows["v"][r].copy(), grp.algebra_take(w, [r])
        out.append((a, motion))
    return out, None


def decode_exchanges(
    messages: Sequence[tuple[int, Any]], grp: RotationGroup, dim: int, run_id: int,
    t_max: float | None = None,
) -> list[tuple[int, Motion | None, str | None]]:
    """Several agents' AgentStates [(agent, msg), ...] -> [(agent, Motion, None) or
    (agent, None, reason), ...] in their order: what ``decode_exchange`` makes of each.

    What a tick takes from its peers, checked together: sender, stamp and layout message by
    message (attribute reads), then the numbers, the rotations (SO(d)) and the W_i (skew) of
    all of them in one array operation each.  A message that fails a check is decoded alone,
    which names its reason; the others keep their values."""
    out: list[tuple[int, Motion | None, str | None]] = [(a, None, None) for a, _ in messages]
    batch: list[tuple[int, float, int]] = []  # (position, t, key) of the well-formed ones
    kinds: set[bool] = set()  # second order (with v and W) or not, of those
    for pos, (agent, msg) in enumerate(messages):
        stamp = (header_time(msg, t_max)[0]
                 if msg.run_id == run_id and msg.agent == agent else None)
        second = len(msg.velocity) == dim and len(msg.angular_velocity) == dim * dim
        laid = (len(msg.centroid) == dim and len(msg.rotation) == dim * dim
                and (second or not (len(msg.velocity) or len(msg.angular_velocity))))
        if stamp is None or not laid or kinds - {second}:
            out[pos] = (agent, *decode_exchange(msg, grp, dim, run_id, agent, t_max))
            continue
        kinds.add(second)
        batch.append((pos, *stamp))
    if batch:
        _decode_together(messages, batch, grp, dim, run_id, t_max, out)
    return out


def _decode_together(
    messages: Sequence[tuple[int, Any]], batch: list[tuple[int, float, int]],
    grp: RotationGroup, dim: int, run_id: int, t_max: float | None,
    out: list[tuple[int, Motion | None, str | None]],
) -> None:
    """``decode_exchanges``' array checks of the well-formed messages at ``batch`` (all of one
    order); every one of them decoded alone if one fails."""
    msgs = [messages[pos][1] for pos, _, _ in batch]
    n, second = len(msgs), len(msgs[0].velocity) > 0
    names = {"x": "centroid", "v": "velocity", "rot": "rotation", "w": "angular_velocity"}
    rows = {label: np.array([np.frombuffer(getattr(m, name), dtype=float) for m in msgs])
            for label, name in names.items() if second or label in ("x", "rot")}
    reason = next((r for r in map(bad_numbers, rows.values()) if r), None)
    reason = reason or bad_rotation(rows["rot"].reshape(n, dim, dim))
    if not reason and second:
        reason = bad_skew(rows["w"].reshape(n, dim, dim))
    if reason:
        for pos, _, _ in batch:
            agent, msg = messages[pos]
            out[pos] = (agent, *decode_exchange(msg, grp, dim, run_id, agent, t_max))
        return
    rot = grp.from_matrices(rows["rot"].reshape(n, dim, dim))
    w = grp.algebra_from_skew(rows["w"].reshape(n, dim, dim)) if second else None
    for r, (pos, t, key) in enumerate(batch):
        motion = Motion(t, key, rows["x"][r], grp.take(rot, [r]))
        if w is not None:
            motion.v, motion.w = rows["v"][r], grp.algebra_take(w, [r])
        out[pos] = (messages[pos][0], motion, None)
