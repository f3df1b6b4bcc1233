"""Results as data: the run record every agent process and the monitor emit.

A ``RunRecord`` travels as one JSON line: the last line a process prints on stdout,
and, latched, on the ensemble's ``status`` topic while it runs.  Whoever reads
results (the runner, the benchmarks, the tests) reads them with ``run_records``;
``describe()`` is the human-readable line printed above it.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping
from dataclasses import asdict, dataclass, field, fields

RECORD_KEY = "polymatch_run_record"
RECORD_VERSION = 1


def drop_summary(counts: Mapping[str, int]) -> str:
    """'no messages dropped' or 'dropped N messages (reason: n, ...)'."""
    if not counts:
        return "no messages dropped"
    parts = ", ".join(f"{r}: {n}" for r, n in sorted(counts.items()))
    return f"dropped {sum(counts.values())} messages ({parts})"


@dataclass
class RunRecord:
    """What one process did: ``role`` agent (hosting ``agents``) or monitor.

    ``t`` simulated time reached; ``steps`` integrator steps and ``rounds`` stage rounds
    (lockstep; a realtime tick is one round); ``rounds_per_second`` over the run's wall time
    (lockstep: after the first round, which waits for the last peer to start);
    ``ms_per_round`` publish/wait/other split (lockstep; realtime: CPU per tick of the whole
    process); ``late_ticks`` realtime ticks started
    more than one period late; ``dropped`` counts per reason; ``peers`` the agents whose
    messages the process needs and ``stage_subscriptions`` its stage-topic subscriptions
    (lockstep; on a communication graph only the in-neighbours); ``clock_offsets`` {peer: s its
    clock is ahead of this one}, estimated from its pose stamps (realtime); monitor:
    ``diameter`` of its last report, ``agents_heard`` in it, ``reports`` published.
    ``n_agents`` the ensemble's size and ``node`` the process's fully qualified node name
    (agents): what ``polymatch set`` waits for before it calls every agent node.
    ``resumed_at``: the step a restarted lockstep process resumed at (None: not restarted).
    ``first_round_at``: wall-clock time (s since the epoch) the process's first lockstep round
    completed (None before); ``max_rss_mb``: the process's peak resident memory (MB).
    ``run_id``: the run the process belongs to (its ``run_id`` parameter): the runner reads only
    its own run's records.
    """

    role: str
    mode: str
    t: float
    agents: tuple[int, ...] = ()
    finished: bool = False
    steps: int = 0
    rounds: int = 0
    rounds_per_second: float = 0.0
    ms_per_round: dict[str, float] = field(default_factory=dict)
    late_ticks: int = 0
    matched_after: float | None = None
    dropped: dict[str, int] = field(default_factory=dict)
    diameter: float | None = None
    agents_heard: int = 0
    reports: int = 0
    peers: tuple[int, ...] = ()
    stage_subscriptions: int = 0
    clock_offsets: dict[int, float] = field(default_factory=dict)
    n_agents: int = 0
    node: str = ""
    resumed_at: int | None = None
    run_id: int = 0
    first_round_at: float | None = None
    max_rss_mb: float = 0.0

    @property
    def dropped_total(self) -> int:
        return sum(self.dropped.values())

    def to_json(self) -> str:
        data = asdict(self)
        data["agents"] = list(self.agents)
        data["peers"] = list(self.peers)
        return json.dumps({RECORD_KEY: RECORD_VERSION, **data})

    @classmethod
    def from_json(cls, text: str) -> RunRecord | None:
        """The record of a JSON line, or None for any other line (never raises)."""
        text = text.strip()
        if not text.startswith("{"):
            return None
        try:
            data = json.loads(text)
            if not isinstance(data, dict) or data.pop(RECORD_KEY, None) != RECORD_VERSION:
                return None
            known = {f.name for f in fields(cls)}
            rec = cls(**{k: v for k, v in data.items() if k in known})
            rec.agents = tuple(int(a) for a in rec.agents)
            rec.peers = tuple(int(a) for a in rec.peers)
            rec.stage_subscriptions = int(rec.stage_subscriptions)
            rec.n_agents, rec.node = int(rec.n_agents), str(rec.node)
            rec.dropped = {str(k): int(v) for k, v in dict(rec.dropped).items()}
            rec.clock_offsets = {int(k): float(v) for k, v in dict(rec.clock_offsets).items()}
            rec.t = float(rec.t)
            return rec if math.isfinite(rec.t) else None
        except (TypeError, ValueError, AttributeError):
            return None

    def name(self) -> str:
        return "monitor" if self.role == "monitor" else "agent " + ",".join(map(str, self.agents))

    def describe(self) -> str:
        """The line for people (`polymatch run -v` shows the agents')."""
        if self.role == "monitor":
            return (
                f"monitor: last report t = {self.t:.6g}, matching diameter {self.diameter:.3e}, "
                f"{self.agents_heard} agents heard, {self.reports} reports; "
                f"{drop_summary(self.dropped)}"
            )
        if self.mode == "lockstep":
            split = ", ".join(f"{k} {v:.2f}" for k, v in self.ms_per_round.items())
            text = (
                f"finished at t = {self.t:.6g} after {self.steps} steps ({self.rounds} rounds, "
                f"{self.rounds_per_second:.1f} rounds/s; ms per round: {split})"
            )
        else:
            text = (
                f"finished at t = {self.t:.6g} after {self.steps} realtime steps, "
                f"{self.late_ticks} started more than one period late"
            )
            if "cpu" in self.ms_per_round:
                text += f" (CPU {self.ms_per_round['cpu']:.2f} ms per tick)"
        if self.matched_after is not None:
            text += f"; peers matched after {self.matched_after:.2f} s"
        if self.resumed_at is not None:
            text += f"; restarted, resumed at step {self.resumed_at}"
        return f"{self.name()}: {text}; {drop_summary(self.dropped)}"


def run_records(lines: Iterable[str]) -> list[RunRecord]:
    """Every run record among ``lines`` (text lines, e.g. a process's output), in order."""
    out = []
    for line in lines:
        rec = RunRecord.from_json(line)
        if rec is not None:
            out.append(rec)
    return out
