"""What both agent modes share: which agents a process hosts and hears, drop counting, lean nodes.

Each mode's exchange (``lockstep.LockstepExchange``, ``realtime.PeerTable``) produces the
*ensemble* the core's steppers ask for: per group, arrays (x, rot, v) of the agents that
take part, in agent-index order, with the process's own rows at their current stage
values (``wire.assemble``).  The core then computes the mean field of (A-1)/(A-2) from
them exactly as the centralised simulator does.
"""

from __future__ import annotations

import itertools
import math
import time
from collections import Counter
from collections.abc import Callable, Iterable, Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from ...core.errors import PolymatchError
from ...core.model import System
from .. import wire

if TYPE_CHECKING:
    from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.impl.rcutils_logger import RcutilsLogger
    from rclpy.node import Node
    from rclpy.subscription import Subscription

    from ...core.model import Model

#: a message's middleware info as rclpy passes it to a callback (``received_timestamp``, ...)
MessageInfo = Mapping[str, Any]


class Layout:
    """Which agents a process hosts and which peers each of them needs.

    ``local`` are global agent indices.  ``agents_per_process`` K gives the
    runner's partition (process p hosts [pK, (p+1)K), block p); it counts how many remote
    processes subscribe to each local stage topic, and with K > 1 names the block topics.
    On a communication graph (``sparse``) an agent needs only what ``System.sources`` names
    at any stage (its in-neighbours once the centroids are integrated, ``simulate.prepare``);
    otherwise every agent of its group, and every agent under the F-2 inter-group potential.
    """

    def __init__(self, model: Model, local: Iterable[int], agents_per_process: int = 1) -> None:
        self.model = model
        self.local = sorted(set(int(a) for a in local))
        self.k = max(1, int(agents_per_process))
        self.owner = {a: model.group_of(a) for a in range(model.n_agents)}
        self.sparse = not model.inter_group and any(g.graph is not None for g in model.groups)
        self._system = System(model) if self.sparse else None
        self._subscribers: dict[tuple[tuple[int, ...], int], int] = {}
        self.rows: list[np.ndarray] = []
        for gi, g in enumerate(model.groups):
            self.rows.append(
                np.array([a - g.start for a in self.local if self.owner[a][0] == gi], dtype=int)
            )
        self.local_groups = [gi for gi, r in enumerate(self.rows) if len(r)]
        needed = set().union(*(self.sources(a) for a in self.local))
        self.peers = sorted(needed - set(self.local))
        self.groups_needed = sorted({self.owner[a][0] for a in needed | set(self.local)})

    def sources(self, agent: int) -> set[int]:
        """Global indices of the agents whose stage messages ``agent`` needs (itself included
        when the whole group is needed)."""
        gi, row = self.owner[agent]
        g = self.model.groups[gi]
        if self.model.inter_group:
            return set(range(self.model.n_agents))
        if not self.sparse or g.graph is None or self._system is None:
            return set(g.indices)
        near: set[int] = set()
        for first in (True, False):
            for rows in self._system.sources(gi, row, first).values():
                near.update(g.start + int(r) for r in rows)
        return near

    def process_of(self, agent: int) -> int:
        return agent // self.k

    @property
    def blocks(self) -> bool:
        """Packed processes (K > 1) exchange one message per block of K agents and round."""
        return self.k > 1

    def local_blocks(self) -> dict[int, list[int]]:
        """Block -> the local agents in it (one block unless ``--only`` cut across one)."""
        out: dict[int, list[int]] = {}
        for a in self.local:
            out.setdefault(self.process_of(a), []).append(a)
        return out

    def peer_blocks(self) -> list[int]:
        """The blocks that hold the peers (their stage rows come in those blocks' messages)."""
        return sorted({self.process_of(a) for a in self.peers})

    def expected_block_subscribers(self, block: int) -> int:
        """Remote processes that need some local agent of ``block``."""
        return self._remote_readers(tuple(self.local_blocks()[block]), block)

    def expected_subscribers(self, agent: int) -> int:
        """Remote processes that need ``agent``'s stage messages."""
        return self._remote_readers((agent,), self.process_of(agent))

    def _remote_readers(self, agents: tuple[int, ...], home: int) -> int:
        """Processes other than ``home`` hosting an agent that needs one of ``agents``."""
        key = (agents, home)
        if key not in self._subscribers:
            self._subscribers[key] = len({
                self.process_of(b)
                for b in range(self.model.n_agents)
                if self.process_of(b) != home and not self.sources(b).isdisjoint(agents)
            })
        return self._subscribers[key]


class DropCounter:
    """Counts dropped messages by reason and warns at most once a second per reason.

    The period is checked here, before the logger is called: rclpy's own
    ``throttle_duration_sec`` first identifies the caller (a stack inspection with file-path
    lookups) on every call, and under a flood of malformed messages that alone took most of
    a lockstep agent's time (py-spy, ``test_rogue_publisher_changes_nothing_...``).
    """

    LOG_PERIOD = 1.0  # s between two warnings of one reason

    def __init__(self, logger: RcutilsLogger) -> None:
        self.logger = logger
        self.counts: Counter[str] = Counter()
        self._warned: dict[str, float] = {}  # reason -> monotonic time of its last warning

    def __call__(self, source: str, reason: str) -> None:
        self.counts[reason] += 1
        now = time.monotonic()
        if now - self._warned.get(reason, -math.inf) < self.LOG_PERIOD:
            return
        self._warned[reason] = now
        self.logger.warning(
            f"dropped a message from {source}: {reason} ({self.counts[reason]} so far)"
        )

    @property
    def total(self) -> int:
        return sum(self.counts.values())

    def summary(self) -> str:
        return wire.drop_summary(self.counts)


class RoundTimeout(PolymatchError):
    """A lockstep round that did not complete: a peer vanished (exit code 1)."""


def lean_node(name: str, namespace: str | None = None) -> tuple[Node, SingleThreadedExecutor]:
    """A node with nothing but what the exchange adds: no parameter services, no rosout.

    rclpy's executor rebuilds its wait set from every entity of its nodes at each
    spin, so the lockstep stages get a node (and an executor) of their own.  It ignores
    the process's remap rules (``-r __node:=`` would give it the agent node's name): its
    topic names are resolved by the agent node (``wire.publisher(..., resolver=node)``).
    """
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node

    node = Node(
        name,
        namespace=namespace,
        use_global_arguments=False,
        start_parameter_services=False,
        enable_rosout=False,
    )
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    return node, executor


class LeanReaders:
    """Readers on a lean node of their own (``lean_node``), taken when their owner asks
    (``drain``), not as their messages arrive: the hot path waits on nothing but what it needs.

    ``drain`` takes each reader's messages straight from the middleware, without a wait: an
    executor's spin builds a wait set of every reader for each message it hands over, which
    cost a realtime agent of one process most of its tick with 15 peers.

    Topic names are resolved by ``resolver`` (the process's own node); each callback gets the
    message and its middleware info (``received_at``)."""

    def __init__(self, resolver: Node, suffix: str) -> None:
        self.node, self.executor = lean_node(
            resolver.get_name() + suffix, resolver.get_namespace()
        )
        self.resolver = resolver
        self.events = quiet_events()[1]
        self.taken = 0  # messages taken (whatever the callback made of them)
        self.readers = 0
        self.subscriptions: list[
            tuple[Subscription, Callable[[Any, MessageInfo], None] | None]] = []

    def subscribe(self, key: str, callback: Callable[[Any, MessageInfo], None] | None,
                  dim: int, agent: int, mode: str) -> Subscription:
        """A reader of ``key`` for ``agent``; ``callback(msg, info)``, or None for a reader
        only ``take_newest`` reads."""
        from .. import wire

        def counted(msg: Any, info: MessageInfo) -> None:
            self.taken += 1
            if callback is not None:
                callback(msg, info)

        self.readers += 1
        sub = wire.subscription(self.node, key, counted, dim, agent, mode=mode,
                                resolver=self.resolver, event_callbacks=self.events)
        self.subscriptions.append((sub, callback))
        return sub

    def drain(self, per_reader: int | None = None) -> None:
        """Take what the readers hold, at most ``per_reader`` messages of each (None: all)."""
        for sub, callback in self.subscriptions:
            for _ in range(per_reader) if per_reader is not None else itertools.count():
                with sub.handle:
                    got = sub.handle.take_message(sub.msg_type, sub.raw)
                if got is None:
                    break
                self.taken += 1
                if callback is not None:
                    callback(*got)

    def take_newest(self, bound: int = 4) -> list[tuple[int, Any, MessageInfo]]:
        """(reader, message, info) of the newest message each reader holds, in the order the
        readers were made, taking at most ``bound`` of each (the older ones taken are counted
        and left: a newer one supersedes them).  The readers' callbacks are not called: the
        caller decodes what the tick needs, all at once."""
        out = []
        for i, (sub, _) in enumerate(self.subscriptions):
            newest = None
            for _ in range(bound):
                with sub.handle:
                    got = sub.handle.take_message(sub.msg_type, sub.raw)
                if got is None:
                    break
                self.taken += 1
                newest = got
            if newest is not None:
                out.append((i, *newest))
        return out

    def destroy(self) -> None:
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()


def received_at(info: MessageInfo | None) -> tuple[float, float]:
    """(wall-clock, monotonic) time at which the middleware received a message: its
    ``received_timestamp`` (ns since the epoch), or now where the middleware gives none."""
    now_wall, now_mono = time.time(), time.monotonic()
    stamp = info.get("received_timestamp") if info else None
    if not stamp:
        return now_wall, now_mono
    wall = min(stamp * 1e-9, now_wall)
    return wall, now_mono - (now_wall - wall)


def quiet_events() -> tuple[PublisherEventCallbacks, SubscriptionEventCallbacks]:
    """(publisher, subscription) event callbacks without rclpy's default QoS-event waitables."""
    from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks

    return (
        PublisherEventCallbacks(use_default_callbacks=False),
        SubscriptionEventCallbacks(use_default_callbacks=False),
    )
