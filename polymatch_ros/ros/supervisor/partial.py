"""What a run that ended early still has: each agent's last state, and its time.

A run interrupted (Ctrl-C, SIGTERM), failed or timed out has no final pose from every agent.
Its ``--save`` then holds, per agent, the later of its final pose (if it sent one) and its
process's last checkpoint (``wire.checkpoint``: the state at the start of its last step);
an agent of which neither exists (its process never stepped) keeps its initial state at
t = 0.  The file says it is partial, and every agent's time is in it.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

from ...core.model import State
from .. import wire

if TYPE_CHECKING:
    from ...core.scenes.scene import Scene
    from ...core.so import RotationGroup
    from ..wire.checkpoint import Checkpoint

#: agent -> (its simulated time, its row)
AgentRows = dict[int, tuple[float, wire.Row]]


def checkpoint_rows(scene: Scene, agents: Sequence[int], found: Checkpoint,
                    computed_in: RotationGroup | None = None) -> AgentRows:
    """The poses of a process's checkpoint (its local state), by global agent index, in the
    scene's representation; ``computed_in``: the agents' own, where it differs (a projection
    integrator computes with matrices in 2-D, ``core.stepping.simulate.prepare``)."""
    model, grp = scene.model, scene.model.rotations
    own = grp if computed_in is None else computed_in
    out: AgentRows = {}
    for gi, gs in enumerate(found.state.groups):
        g = model.groups[gi]
        local = sorted(a for a in agents if g.start <= a < g.start + g.size)
        if gs is None or not local:
            continue
        for r, a in enumerate(local):
            rot = own.take(gs.rot, [r])
            if own.name != grp.name:
                rot = grp.from_matrices(own.to_matrices(rot))
            out[a] = (found.t, wire.Row(gs.x[r].copy(), rot))
    return out


def last_state(scene: Scene, finals: Mapping[int, tuple[float, wire.Row]],
               pieces: Sequence[tuple[Sequence[int], Checkpoint | None]],
               computed_in: RotationGroup | None = None) -> tuple[State, dict]:
    """(the ensemble's poses from every agent's latest row, {agent: its time}); ``finals``
    the final poses heard, ``pieces`` each process's agents and checkpoint (its rotations in
    ``computed_in``, the agents' representation, if not the scene's)."""
    latest: AgentRows = {}
    for agents, found in pieces:
        if found is not None:
            latest.update(checkpoint_rows(scene, agents, found, computed_in))
    for a, (t, row) in finals.items():
        if a not in latest or t >= latest[a][0]:
            latest[a] = (t, row)
    model, grp = scene.model, scene.model.rotations
    times: dict[int, float] = {}
    rows: dict[int, wire.Row] = {}
    for gi, g in enumerate(model.groups):
        initial = scene.initial.groups[gi]
        assert initial is not None  # a scene's initial state has every group
        for a in g.indices:
            if a in latest:
                times[a], rows[a] = latest[a]
            else:  # never stepped: where it began
                r = a - g.start
                times[a] = 0.0
                rows[a] = wire.Row(initial.x[r], grp.take(initial.rot, [r]))
    return wire.state_of(model, rows, min(times.values())), times
