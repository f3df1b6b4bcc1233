"""Realtime: each peer's wall-clock offset, estimated from the stamps of its poses.

Realtime agents share one schedule: the pose of simulated time t is published at wall-clock time
``epoch + t / time_scale`` on the publisher's own clock (``epoch`` is the runner's ``start``).
A pose that arrives at local time ``arrival`` therefore shows

    (epoch + t / time_scale) - arrival = offset - latency,

where ``offset`` is the peer's clock minus ours and ``latency`` >= 0 the transport delay (plus
any lag of the peer behind its schedule).  The largest value over a window of recent poses -
the least delayed one, as NTP's minimum-delay filter - estimates the offset.  The ensemble's
clock is the lead host's epoch, so an offset of a peer on another host is what its clock is
ahead of this one; a large one skews who counts as silent (``peer_timeout``) and which
poses are current (Theorem 4.2 assumes bounded delays).
"""

from __future__ import annotations

from collections import defaultdict, deque

WINDOW = 50  # poses per peer the estimate looks back over


class ClockOffsets:
    """Offset estimates per peer; ``over_threshold`` names each peer once when it crosses."""

    def __init__(self, time_scale: float, threshold: float, window: int = WINDOW) -> None:
        self.time_scale, self.threshold = float(time_scale), float(threshold)
        self.epoch: float | None = None
        self.samples: defaultdict[int, deque[float]] = defaultdict(lambda: deque(maxlen=window))
        self.warned: set[int] = set()

    def start(self, epoch: float) -> None:
        """The wall-clock time of t = 0 (before it, stamps say nothing of the clocks)."""
        self.epoch = float(epoch)

    def add(self, agent: int, t: float, arrival: float) -> None:
        """A pose of ``agent`` stamped ``t`` (simulated s) arrived at wall-clock ``arrival``."""
        if self.epoch is None or t <= 0.0:
            return
        self.samples[agent].append(self.epoch + t / self.time_scale - arrival)

    def offsets(self) -> dict[int, float]:
        """{agent: estimated offset (s) of its clock ahead of ours}."""
        return {a: max(values) for a, values in self.samples.items() if values}

    def over_threshold(self) -> list[tuple[int, float]]:
        """[(agent, offset)] of peers whose |offset| first exceeds the threshold now."""
        out = []
        for agent, offset in sorted(self.offsets().items()):
            if abs(offset) > self.threshold and agent not in self.warned:
                self.warned.add(agent)
                out.append((agent, offset))
            elif abs(offset) <= self.threshold:
                self.warned.discard(agent)
        return out
