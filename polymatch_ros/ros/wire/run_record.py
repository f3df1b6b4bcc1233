"""Results as data: the run record every agent process and the monitor emit.

A ``RunRecord`` travels, latched, on the ensemble's ``status`` topic while a process runs, as
a ``polymatch_interfaces/msg/RunRecord`` (``to_msg``, ``from_msg``), and as one JSON line, the
last line the process prints on stdout.  Whoever reads results (the runner, the benchmarks, the
tests) reads them with ``run_records``; ``describe()`` is the human-readable line printed
above it.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Iterable, Mapping
from dataclasses import asdict, dataclass, field, fields
from typing import Any

from .modes import Mode

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

    def to_msg(self) -> Any:
        """The record as a ``polymatch_interfaces/msg/RunRecord`` (NaN and -1 stand for None)."""
        from polymatch_interfaces.msg import NamedValue, ReasonCount
        from polymatch_interfaces.msg import RunRecord as Msg

        nan = math.nan
        msg = Msg(run_id=int(self.run_id), role=self.role, mode=self.mode, t=float(self.t),
                  agents=list(self.agents), finished=self.finished, steps=int(self.steps),
                  rounds=int(self.rounds), rounds_per_second=float(self.rounds_per_second),
                  late_ticks=int(self.late_ticks),
                  matched_after=nan if self.matched_after is None else float(self.matched_after),
                  diameter=nan if self.diameter is None else float(self.diameter),
                  agents_heard=int(self.agents_heard), reports=int(self.reports),
                  peers=list(self.peers), stage_subscriptions=int(self.stage_subscriptions),
                  n_agents=int(self.n_agents), node=self.node,
                  resumed_at=-1 if self.resumed_at is None else int(self.resumed_at),
                  first_round_at=nan if self.first_round_at is None
                  else float(self.first_round_at),
                  max_rss_mb=float(self.max_rss_mb))
        msg.ms_per_round = [NamedValue(name=k, value=float(v))
                            for k, v in self.ms_per_round.items()]
        msg.dropped = [ReasonCount(reason=k, count=int(v)) for k, v in self.dropped.items()]
        msg.clock_offsets = [NamedValue(name=str(k), value=float(v))
                             for k, v in self.clock_offsets.items()]
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(time.time_ns(), 1_000_000_000)
        return msg

    @classmethod
    def from_msg(cls, msg: Any) -> RunRecord | None:
        """The record of a ``RunRecord`` message, or None if it is not a valid one (never
        raises)."""
        try:
            if msg.role not in ("agent", "monitor") or not math.isfinite(msg.t):
                return None
            def maybe(value: float) -> float | None:
                return None if math.isnan(value) else float(value)

            return cls(role=msg.role, mode=msg.mode, t=float(msg.t), agents=tuple(msg.agents),
                       finished=bool(msg.finished), steps=msg.steps, rounds=msg.rounds,
                       rounds_per_second=msg.rounds_per_second,
                       ms_per_round={v.name: v.value for v in msg.ms_per_round},
                       late_ticks=msg.late_ticks, matched_after=maybe(msg.matched_after),
                       dropped={c.reason: int(c.count) for c in msg.dropped},
                       diameter=maybe(msg.diameter), agents_heard=msg.agents_heard,
                       reports=msg.reports, peers=tuple(msg.peers),
                       stage_subscriptions=msg.stage_subscriptions,
                       clock_offsets={int(v.name): v.value for v in msg.clock_offsets},
                       n_agents=msg.n_agents, node=msg.node,
                       resumed_at=None if msg.resumed_at < 0 else int(msg.resumed_at),
                       run_id=int(msg.run_id), first_round_at=maybe(msg.first_round_at),
                       max_rss_mb=msg.max_rss_mb)
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
        if self.mode == Mode.LOCKSTEP:  # a record from the network may name any mode
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


def echoed_run_records(lines: Iterable[str]) -> list[RunRecord]:
    """Every run record among ``lines`` that ``polymatch echo --json`` printed of a ``status``
    topic (a ``RunRecord`` message a line), in order; other lines are passed over."""
    from types import SimpleNamespace

    def attributes(value: Any) -> Any:
        if isinstance(value, dict):
            return SimpleNamespace(**{k: attributes(v) for k, v in value.items()})
        if isinstance(value, list):
            return [attributes(v) for v in value]
        return value

    out = []
    for line in lines:
        try:
            data = json.loads(line)
        except ValueError:
            continue
        rec = RunRecord.from_msg(attributes(data)) if isinstance(data, dict) else None
        if rec is not None:
            out.append(rec)
    return out
