"""The monitor's lockstep intake of block messages: held by step, decoded only when reported.

Packed lockstep processes send their agents' states a block message a step (at the monitor's
pace, ``agents.state_stride``).  The monitor needs, at each report, the latest step that every
agent has reached, and between reports only which step that is (``/clock``).  So a block message
is read for its sender and stamp alone and held under its step; once a step holds every agent,
it is the completed step, and the steps before it are forgotten undecoded.  Only the step a
report shows is decoded (``wire.decode_exchange_block``), inside the report, whose CPU time the
monitor caps (``monitor.REPORT_CPU_SHARE``): what the monitor spends between reports no longer
grows with the agents it watches.
"""

from __future__ import annotations

from collections import defaultdict
from typing import TYPE_CHECKING, Any

from .. import wire
from ..wire.stage_rows import header_time

if TYPE_CHECKING:
    from ...core.so import RotationGroup

#: a held message: (block, message, monotonic time it was heard)
Held = tuple[int, Any, float]


class HeldSteps:
    """Block messages by step (the stamp's integer ns key), undecoded, until a step is
    complete: the states of all ``n`` agents heard."""

    def __init__(self, n: int, k: int, run_id: int, t_max: float | None,
                 grp: RotationGroup, dim: int) -> None:
        self.n, self.k, self.run_id, self.t_max = n, k, int(run_id), t_max
        self.grp, self.dim = grp, dim  # what a refused message is decoded with, for its reason
        # step key -> {(block, first agent): (block, message, heard)}
        self.steps: defaultdict[int, dict[tuple[int, int], Held]] = defaultdict(dict)
        self.agents: defaultdict[int, int] = defaultdict(int)  # step key -> agents held

    def hold(self, block: int, msg: Any, heard: float, completed: int) -> str | None:
        """Keep ``msg`` (block ``block``'s states of one step) under its step; None if held,
        else why not: 'repeat' (that step's message of these agents is held, or the step is
        the completed one), 'stale' (a step before the completed one), or the reason the
        decoder refuses it (another run, another block, a malformed message)."""
        stamp = (header_time(msg, self.t_max)[0]
                 if msg.run_id == self.run_id and msg.block == block and len(msg.agents)
                 else None)
        if stamp is None:
            return wire.decode_exchange_block(msg, self.grp, self.dim, self.run_id, block,
                                              self.k, self.t_max)[1] or "malformed layout"
        key = stamp[1]
        if key <= completed:
            return "repeat" if key == completed else "stale"
        slot = (block, int(msg.agents[0]))
        if slot in self.steps[key]:
            return "repeat"
        self.steps[key][slot] = (block, msg, heard)
        self.agents[key] += len(msg.agents)
        return None

    def newest_complete(self) -> int | None:
        """The latest step held with every agent's state, or None."""
        full = [key for key, count in self.agents.items() if count >= self.n]
        return max(full) if full else None

    def take(self, key: int) -> list[Held]:
        """The messages of step ``key``; it and every step before it are forgotten."""
        out = list(self.steps.get(key, {}).values())
        for old in [k for k in self.steps if k <= key]:
            del self.steps[old]
            self.agents.pop(old, None)
        return out

