"""Per-agent records -> one group's arrays: what every reader of poses or stages assembles."""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from types import SimpleNamespace
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from ...core.model import GroupState, Model, State
    from ...core.so import RotationGroup
    from .stage_rows import StageRows


@dataclass
class Row:
    """One agent's values as heard: centroid x, one-row rotation, velocity v, algebra row w."""

    x: np.ndarray | float
    rot: np.ndarray | None = None
    v: np.ndarray | None = None
    w: np.ndarray | None = None


def assemble(grp: RotationGroup, dim: int, rows: Mapping[int, Row],
             local: tuple[Sequence[int] | np.ndarray, GroupState | None] | None = None,
             with_rot: bool = True, with_v: bool = False, with_w: bool = False,
             full: bool = False) -> SimpleNamespace:
    """Group arrays (x, rot, v, w, index) in row order from ``rows`` {group row: Row}.

    ``local`` = (rows, GroupState): the process's own rows at their current (stage) values,
    put in with whole-array writes.  ``index`` lists the rows present (None with ``full``:
    every row of the group is).  A missing velocity is zero; ``with_w`` needs every row's w.
    The core computes the mean field of (A-1)/(A-2) from these arrays as the centralised
    simulator does, so the numbers are identical.
    """
    local_rows = [] if local is None else [int(r) for r in local[0]]
    index = np.array(sorted(set(rows) | set(local_rows)), dtype=int)
    pos = {row: k for k, row in enumerate(index.tolist())}
    out = _group_arrays(grp, dim, index, with_rot, with_v, full)
    for row, rec in rows.items():
        k = pos[row]
        out.x[k] = rec.x
        if with_rot:
            grp.put(out.rot, [k], rec.rot)  # type: ignore[arg-type]  # rows carry rotations
        if with_v and rec.v is not None:
            out.v[k] = rec.v
    if local is not None and local_rows:
        _put_local(grp, out, [pos[r] for r in local_rows], local[1], with_rot, with_v)
    if with_w:
        out.w = grp.algebra_concat([rows[r].w for r in index.tolist()])  # type: ignore[misc]
    return out


def state_of(model: Model, rows: Mapping[int, Row], t: float,
             velocities: Mapping[int, tuple[np.ndarray, np.ndarray]] | None = None) -> State:
    """The model's State at time ``t`` from every agent's row ({agent: Row}); a second-order
    group gets the (v, w) of ``velocities`` where it has every agent's, else none."""
    from ...core.model import GroupState, State

    groups = []
    for g in model.groups:
        present = {a - g.start: rows[a] for a in g.indices}
        with_v = (model.order == 2 and velocities is not None
                  and all(a in velocities for a in g.indices))
        if with_v:
            assert velocities is not None
            present = {r: Row(row.x, row.rot, *velocities[r + g.start])
                       for r, row in present.items()}
        e = assemble(model.rotations, model.dim, present, with_v=with_v, with_w=with_v,
                     full=True)
        groups.append(GroupState(e.x, e.rot, e.v, e.w))
    return State(t, tuple(groups))


def assemble_rows(grp: RotationGroup, dim: int, start: int, size: int,
                  messages: Iterable[StageRows],
                  local: tuple[Sequence[int] | np.ndarray, GroupState | None] | None = None,
                  with_rot: bool = True, with_v: bool = False,
                  full: bool = False) -> SimpleNamespace:
    """``assemble`` from decoded stage messages (``StageRows``): the rows of the group
    [start, start + size) that each message carries, written array by array.

    The same numbers land in the same places as row by row, so the core's mean field is the
    centralised simulator's, bit for bit; a packed process's round then costs a few array
    writes per peer block instead of Python work per peer agent."""
    parts: list[tuple[np.ndarray, StageRows]] = []
    for m in messages:
        rows = m.agents - start
        inside = (rows >= 0) & (rows < size)
        if inside.all():
            parts.append((rows, m))
        elif inside.any():
            parts.append((rows[inside], m.select(grp, inside)))
    local_rows = np.zeros(0, dtype=int) if local is None else np.asarray(local[0], dtype=int)
    index = np.unique(np.concatenate([rows for rows, _ in parts] + [local_rows]))
    out = _group_arrays(grp, dim, index, with_rot, with_v, full)
    for rows, m in parts:
        at = np.searchsorted(index, rows)
        if m.x is not None:
            out.x[at] = m.x
        if with_rot:
            grp.put(out.rot, at, m.rot)
        if with_v and m.v is not None:
            out.v[at] = m.v
    if local is not None and len(local_rows):
        _put_local(grp, out, np.searchsorted(index, local_rows), local[1], with_rot, with_v)
    return out


def _group_arrays(grp: RotationGroup, dim: int, index: np.ndarray, with_rot: bool,
                  with_v: bool, full: bool) -> SimpleNamespace:
    """Zero centroids and velocities, identity rotations, for the group rows ``index``."""
    n = len(index)
    return SimpleNamespace(
        x=np.zeros((n, dim)),
        rot=grp.identity(n) if with_rot else None,
        v=np.zeros((n, dim)) if with_v else None,
        w=None,
        index=None if full else index,
    )


def _put_local(grp: RotationGroup, out: SimpleNamespace, at: Sequence[int] | np.ndarray,
               gs: GroupState | None, with_rot: bool, with_v: bool) -> None:
    """The process's own rows (their current stage values) at positions ``at`` of ``out``."""
    assert gs is not None  # a stage holds the rows of every local group
    out.x[at] = gs.x
    if with_v:
        out.v[at] = gs.v
    if with_rot:
        grp.put(out.rot, at, gs.rot)
