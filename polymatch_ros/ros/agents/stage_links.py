"""The topics a lockstep process sends and hears stage rows on: one per agent, or one per block.

``AgentLinks`` (one agent per process): ``agent_<i>/stage``, one message per agent and round.
``BlockLinks`` (K > 1 agents per process): ``stages/block_<b>``, one message per round with
the rows of every local agent of block b (agents bK .. bK + K - 1).  A complete graph of N
agents in P processes then moves P (P - 1) messages a round instead of N (N - P): the
per-message cost of DDS and rclpy (take, deserialise, callback) is what bounds a round
on a loaded machine, not the bytes.  A process hears the blocks that hold its peers;
on a graph those are the in-neighbours' blocks only.

Both keep the messages of their last ``keep`` rounds for ``resend`` (two, or a step and two
rounds where a restarted peer may resume: ``checkpoint``) and give the exchange the
same view: which peers are matched, which have gone, and the decoded rows of every
message that arrives (``on_stage``: ``wire.StageRows``, one row or a block's), or a drop
(``on_drop``).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from .. import wire
from ..wire.checkpoint import Kept
from ..wire.intake import quiet_events

if TYPE_CHECKING:
    from rclpy.node import Node
    from rclpy.publisher import Publisher
    from rclpy.subscription import Subscription

    from ...core.model import Request
    from ...core.so import RotationGroup
    from ..wire.intake import Layout

#: a peer's decoded stage message (its rows), and a dropped message (source, reason)
OnStage = Callable[[wire.StageRows], None]
OnDrop = Callable[[str, str], None]


def local_fields(
    grp: RotationGroup, request: Request, layout: Layout
) -> tuple[list[int], dict[str, np.ndarray]]:
    """(agents, label -> rows) of the local agents' stage values, agents in index order."""
    st = request.stage
    agents: list[int] = []
    fields: dict[str, list[np.ndarray]] = {}
    for gi in layout.local_groups:
        gs, g = st.groups[gi], layout.model.groups[gi]
        assert gs is not None  # a local group's rows are in every stage
        agents.extend(int(g.start + r) for r in layout.rows[gi])  # gs holds the local rows only
        n = len(layout.rows[gi])
        rot = gs.rot[:, None] if grp.name == "angle" else grp.to_matrices(gs.rot).reshape(n, -1)
        parts = {"rot": rot}
        if "x" in request.fields:
            parts["x"] = gs.x
        if "v" in request.fields and gs.v is not None:
            parts["v"] = gs.v
        for label, values in parts.items():
            fields.setdefault(label, []).append(values)
    return agents, {label: np.concatenate(v) for label, v in fields.items()}


class _Links:
    """What both kinds share: the sent messages of the last two rounds, matching, resends."""

    # set by each kind: its writers by agent or block, the peers' readers by agent, and the
    # number of remote readers each writer expects
    pubs: dict[int, Publisher]
    writers: dict[int, Subscription]
    expected: Callable[[int], int]

    def __init__(self, node: Node, resolver: Node, layout: Layout, keep: int = 2) -> None:
        self.node, self.resolver, self.layout = node, resolver, layout
        self.keep = max(2, int(keep))
        # (turn, [(publisher, message), ...]) of the last rounds
        self.sent: deque[tuple[int, list[tuple[Publisher, Any]]]] = deque(maxlen=self.keep)
        self._keys: dict[int, int] | None = None  # id(writer) -> its agent or block
        self.events = quiet_events()

    def unheard(self) -> bool:
        """No other process needs this one's stage rows (one process hosts every agent):
        rounds are then not published at all (at 4096 agents in one process, publishing them
        to nobody took a large share of a round)."""
        return all(self.expected(i) == 0 for i in self.pubs)

    def _turn(self) -> int:
        """The message buffer of the next round: none of the rounds kept for ``resend``."""
        return (self.sent[-1][0] + 1) % self.keep if self.sent else 0

    def _publisher(self, key: str, index: int) -> Publisher:
        return wire.publisher(self.node, key, agent=index, resolver=self.resolver,
                              event_callbacks=self.events[0])

    def _subscription(
        self, key: str, index: int, callback: Callable[[Any], None]
    ) -> Subscription:
        return wire.subscription(self.node, key, callback, agent=index, resolver=self.resolver,
                                 event_callbacks=self.events[1])

    def resend(self) -> None:
        for _, sent in self.sent:
            for pub, msg in sent:
                pub.publish(msg)

    def snapshot(self) -> Kept:
        """The kept rounds' messages as data (``checkpoint``): (turn, [(writer key, bytes)])."""
        if self._keys is None:  # the writers are made once, with the links
            self._keys = {id(pub): key for key, pub in self.pubs.items()}
        keys = self._keys
        from rclpy.serialization import serialize_message

        return tuple((turn, tuple((keys[id(pub)], serialize_message(msg)) for pub, msg in sent))
                     for turn, sent in self.sent)

    def restore(self, kept: Kept) -> None:
        """A restarted process keeps again what it had sent before it died (``snapshot``): a
        peer that resumes a step earlier needs those rounds, and only this process has them."""
        from rclpy.serialization import deserialize_message

        rows_msg = wire.message_type("stage")
        self.sent.clear()
        for turn, sent in kept:
            messages = []
            for key, data in sent:
                messages.append((self.pubs[key], deserialize_message(data, rows_msg)))
            self.sent.append((turn, messages))

    def missing_peers(self) -> list[int]:
        return [a for a in self.layout.peers if self.writers[a].get_publisher_count() < 1]

    def matched(self) -> bool:
        """All peers' writers matched, and every expected remote reader of ours."""
        return not self.missing_peers() and all(
            p.get_subscription_count() >= self.expected(i) for i, p in self.pubs.items()
        )

    def flush(self, timeout: float) -> None:
        from rclpy.duration import Duration

        for p in self.pubs.values():
            p.wait_for_all_acked(Duration(seconds=timeout))


class AgentLinks(_Links):
    """One stage topic per agent (a process of one agent)."""

    def __init__(self, node: Node, resolver: Node, layout: Layout,
                 decode: Callable[[Any, int], tuple[wire.StageRows | None, str | None]],
                 on_stage: OnStage, on_drop: OnDrop, keep: int = 2) -> None:
        super().__init__(node, resolver, layout, keep)
        rows_msg = wire.message_type("stage")
        self.pubs = {a: self._publisher("stage", a) for a in layout.local}
        self.expected = layout.expected_subscribers
        self._out = {a: tuple(rows_msg() for _ in range(self.keep))
                     for a in layout.local}
        self.writers = {}  # peer -> its stage subscription

        def receiver(agent: int) -> Callable[[Any], None]:
            def receive(msg: Any) -> None:
                rows, reason = decode(msg, agent)
                if rows is None:
                    on_drop(f"agent {agent}", reason)  # type: ignore[arg-type]  # with None
                else:
                    on_stage(rows)

            return receive

        for a in layout.peers:
            self.writers[a] = self._subscription("stage", a, receiver(a))

    def publish(self, run_id: int, step: int, stage: int, flags: int, t: float,
                agents: Sequence[int], fields: Mapping[str, np.ndarray]) -> None:
        turn = self._turn()
        sent: list[tuple[Publisher, Any]] = []
        for r, a in enumerate(agents):
            msg = self._out[a][turn]
            row = {label: values[r].tolist() for label, values in fields.items()}
            wire.encode_stage(msg, run_id, a, step, stage, flags, t, row)
            self.pubs[a].publish(msg)
            sent.append((self.pubs[a], msg))
        self.sent.append((turn, sent))


class BlockLinks(_Links):
    """One stage topic per block of K agents (packed processes)."""

    def __init__(self, node: Node, resolver: Node, layout: Layout,
                 decode_block: Callable[[Any, int], tuple[wire.StageRows | None, str | None]],
                 on_stage: OnStage, on_drop: OnDrop, keep: int = 2) -> None:
        super().__init__(node, resolver, layout, keep)
        rows_msg = wire.message_type("stage")
        self.local_blocks = layout.local_blocks()
        self.pubs = {b: self._publisher("stage_block", b) for b in self.local_blocks}
        self.expected = layout.expected_block_subscribers
        self._out = {b: tuple(rows_msg() for _ in range(self.keep))
                     for b in self.local_blocks}
        peers = np.array(layout.peers, dtype=int)

        def receiver(block: int) -> Callable[[Any], None]:
            def receive(msg: Any) -> None:
                rows, reason = decode_block(msg, block)
                if rows is None:
                    on_drop(f"block {block}", reason)  # type: ignore[arg-type]  # with None
                    return
                needed = np.isin(rows.agents, peers)  # on a graph a block also carries rows
                if needed.all():                       # nobody here needs
                    on_stage(rows)
                elif needed.any():
                    on_stage(rows.select(layout.model.rotations, needed))

            return receive

        subs = {b: self._subscription("stage_block", b, receiver(b)) for b in layout.peer_blocks()}
        self.writers = {a: subs[layout.process_of(a)] for a in layout.peers}

    def publish(self, run_id: int, step: int, stage: int, flags: int, t: float,
                agents: Sequence[int], fields: Mapping[str, np.ndarray]) -> None:
        turn = self._turn()
        sent: list[tuple[Publisher, Any]] = []
        where = {a: r for r, a in enumerate(agents)}
        for b, members in self.local_blocks.items():
            rows = [where[a] for a in members]
            msg = self._out[b][turn]
            part = {label: values[rows] for label, values in fields.items()}
            wire.encode_block(msg, run_id, b, step, stage, flags, t, members, part)
            self.pubs[b].publish(msg)
            sent.append((self.pubs[b], msg))
        self.sent.append((turn, sent))
