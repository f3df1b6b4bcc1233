"""Realtime: each agent steps on its own wall-clock timer with the latest pose of each peer.

Peers that fall silent longer than ``peer_timeout`` are dropped from the sums of
(A-1)/(A-2) and re-admitted when they speak again (Theorem 4.2 under delays and churn).
On a proximity graph (``graph: {radius: R}``) an agent couples only to the peers within R of
one of its process's agents in the latest poses (``PeerTable.in_range``), as a radio would.
Each peer's clock offset is estimated from its pose stamps (clock_offset.py) and published in
the diagnostics.

A process may host K agents (``-k``): they step together on the process's tick, the numerics
vectorised over them (the core's ``drive`` over the process's rows, as in lockstep), with the
latest states the process has of the other processes' agents, and it publishes their states in
one message a tick (``states/block_<b>``, read as one message per peer process).

A tick's work: sleep until the tick is due, serving the agent node (control, services,
parameters) a few times a second, take what the peers' readers hold (``PeerTable.drain``:
straight from the middleware, the newest state of each peer, decoded together), step,
publish.  The peers' poses do not wake the agent between ticks: their readers keep the
newest (depth 1), and the middleware's reception time stamps each one for the clock offsets
and the silence timeout.
"""

from __future__ import annotations

import time
from collections import defaultdict
from collections.abc import Callable, Iterable
from dataclasses import replace
from types import SimpleNamespace
from typing import TYPE_CHECKING, Any

import numpy as np

from ...core import proximity
from ...core.model import System
from ...core.stepping.simulate import drive
from ...core.stepping.solver import Method
from .. import wire
from ..config.params import declare_resolved
from ..config.runtime_params import SPEC, RuntimeParams
from ..wire.intake import LeanReaders, MessageInfo, received_at
from .agent_base import AgentBase, local_state
from .clock_offset import ClockOffsets

if TYPE_CHECKING:
    from rclpy.executors import Executor
    from rclpy.node import Node

    from ...core.model import Request, State
    from ..config.resolve import ResolvedAgent
    from ..wire.intake import DropCounter, Layout

#: per group the arrays the core asks for (``wire.assemble``), None for groups not needed
Ensemble = tuple[SimpleNamespace | None, ...]
#: s between two spins of the agent node while ticking: control commands, service calls and
#: parameters are taken within this long (as in lockstep)
SERVE_PERIOD = 0.1


class PeerTable:
    """The latest pose (and velocity) heard from each peer, and who is still alive.

    Its readers live on a lean node of their own (``exchange.lean_node``, topic names resolved
    by the agent node): ``drain()`` takes what they hold, at the tick, without waking the agent
    for every pose in between.
    """

    def __init__(self, node: Node, layout: Layout, run_id: int, timeout: float,
                 drops: DropCounter, delay: float, t_max: float | None,
                 clock: ClockOffsets | None = None, velocities: bool = True) -> None:
        self.node, self.layout, self.drops, self.run_id = node, layout, drops, int(run_id)
        self.clock = clock  # ClockOffsets fed with every pose's stamp and arrival, or None
        # injected transport delay (s): a pose is used this long after arrival
        self.delay = float(delay)
        # agent -> [(arrival, kind, values)] not yet delivered
        self.pending: defaultdict[int, list[tuple[float, str, Any]]] = defaultdict(list)
        self.model = layout.model
        self.grp = self.model.rotations
        self.timeout, self.t_max = timeout, t_max
        self.latest: dict[int, SimpleNamespace] = {}  # agent -> (t, x, rot, v, heard)
        self.silent: set[int] = set()
        self.in_range_count: int | None = None  # proximity graphs: peers heard at the last tick
        # group -> radio range R, for the groups on a proximity graph: only these filter peers
        self.radio_ranges = {gi: g.graph.radius for gi, g in enumerate(self.model.groups)
                             if g.graph is not None and g.graph.dynamic}
        dim = self.model.dim
        self.readers = LeanReaders(node, "_peers")
        # the peers' velocities enter the closed-form centroid flow (Proposition 2.1) and a
        # second-order safety filter (``of_agent``): the peers of this process's groups
        self.velocity_from = frozenset(
            a for a in layout.peers if layout.owner[a][0] in layout.local_groups
        ) if velocities and self.model.order == 2 else frozenset()
        # the run's exchange (wire.exchange): pinned to this run's id; packed processes send
        # their agents' states in one message a tick (a block), read as one reader a process
        if layout.blocks:
            for b in layout.peer_blocks():
                self.readers.subscribe("state_block", self._block_receiver(b), dim, b,
                                       wire.Mode.REALTIME)
        else:  # a reader per peer, taken at the tick and decoded all at once (``drain``)
            for a in layout.peers:
                self.readers.subscribe("state", None, dim, a, wire.Mode.REALTIME)
        self.reader_agents = [] if layout.blocks else list(layout.peers)

    @classmethod
    def of_agent(cls, agent: AgentBase, clock: ClockOffsets | None = None) -> PeerTable:
        """The table of a realtime or bridge agent (``AgentBase``), from its parameters; a bridge
        agent (centroids measured, never advanced by the flow) hears them only for its safety
        filter (``core.robots.shaping``)."""
        config = agent.config
        shaper = getattr(agent, "shaper", None)
        velocities = (agent.model.centroids_exact if not agent.mode.drives_robots
                      else shaper is not None and shaper.safety is not None)
        return cls(agent.node, agent.layout, config.run_id, config.peer_timeout, agent.drops,
                   config.delay, agent.scene.t_end, clock, velocities=velocities)

    def _entry(self, agent: int) -> SimpleNamespace:
        return self.latest.setdefault(
            agent, SimpleNamespace(t=-np.inf, x=None, rot=None, v=None, heard=0.0)
        )

    def _heard(self, agent: int, got: wire.Motion, wall: float, mono: float) -> None:
        """A peer's decoded state waits in ``pending`` as (t, offset x, rotation) and, where the
        flow needs it, the centroid velocity, stamped with the time the middleware received it
        (``wall``, ``mono``)."""
        if self.clock is not None:
            self.clock.add(agent, got.t, wall)
        self.pending[agent].append((mono, "pose", (got.t, got.x, got.rot)))
        if got.v is not None and agent in self.velocity_from:
            self.pending[agent].append((mono, "twist", got.v))

    def _block_receiver(self, block: int) -> Callable[[Any, MessageInfo], None]:
        """The callback of one peer process's block topic: each row of a peer as that peer's
        message (``_heard``); a malformed row drops the whole message."""
        peers = set(self.layout.peers)

        def receive(msg: Any, info: MessageInfo) -> None:
            got, reason = wire.decode_exchange_block(
                msg, self.grp, self.model.dim, self.run_id, block, self.layout.k, self.t_max)
            if got is None:
                self.drops(f"block {block}", reason)  # type: ignore[arg-type]  # with None
                return
            wall, mono = received_at(info)
            for agent, motion in got:
                if agent in peers:
                    self._heard(agent, motion, wall, mono)

        return receive

    def drain(self) -> None:
        """Take the poses and twists the peers' readers hold (depth 1: one of each per peer,
        unless more come while they are taken).  Per-peer readers: the newest state of each,
        decoded together (``wire.decode_exchanges``); another run's message, or anything
        malformed, is dropped and counted."""
        if self.layout.blocks:
            self.readers.drain(per_reader=4)
            return
        taken = self.readers.take_newest(bound=1)  # depth 1: a reader holds one at most
        got = wire.decode_exchanges([(self.reader_agents[i], msg) for i, msg, _ in taken],
                                    self.grp, self.model.dim, self.run_id, self.t_max)
        for (_, _, info), (agent, motion, reason) in zip(taken, got):
            if motion is None:
                self.drops(f"agent {agent}", reason)  # type: ignore[arg-type]  # with None
                continue
            self._heard(agent, motion, *received_at(info))

    def destroy(self) -> None:
        """The readers' lean node (lifecycle cleanup, shutdown)."""
        self.readers.destroy()

    def _deliver(self, now: float) -> None:
        """Move every pose and velocity that has waited ``delay`` into the table."""
        for agent, queue in self.pending.items():
            keep: list[tuple[float, str, Any]] = []
            for arrival, kind, values in queue:
                if now - arrival < self.delay:
                    keep.append((arrival, kind, values))
                    continue
                e = self._entry(agent)
                if kind == "twist":
                    e.v = values
                    continue
                t, x, rot = values
                if t < e.t and agent not in self.silent:
                    self.drops(f"agent {agent}", "out-of-order pose")
                    continue
                # an older stamp from a peer that had fallen silent is a restarted peer: a new
                # incarnation, admitted from its own clock
                e.t, e.x, e.rot, e.heard = t, x, rot, arrival + self.delay
                if agent in self.silent:
                    self.silent.discard(agent)
                    self.node.get_logger().info(f"agent {agent} is back: re-admitted to the sums")
            queue[:] = keep

    def newest_time(self) -> float | None:
        """The newest simulated time heard from any peer (None if none): the ensemble's clock."""
        self.drain()
        self._deliver(time.monotonic())
        times = [e.t for e in self.latest.values() if e.x is not None and np.isfinite(e.t)]
        return max(times) if times else None

    def active(self) -> list[int]:
        """Peers heard within the timeout (what their readers hold taken first); logs once
        when one falls silent."""
        self.drain()
        now = time.monotonic()
        self._deliver(now)
        alive = []
        for a in self.layout.peers:
            e = self.latest.get(a)
            if e is None or e.x is None:
                continue
            if now - e.heard > self.timeout:
                if a not in self.silent:
                    self.silent.add(a)
                    self.node.get_logger().warning(
                        f"agent {a} silent for {self.timeout:g} s: dropped from the sums"
                    )
                continue
            alive.append(a)
        return alive

    def in_range(self, alive: list[int], state: State) -> list[int]:
        """The peers a radio hears: on a proximity graph those of ``alive`` within R of one of
        this process's agents (``state``) in their latest poses; every other peer as it is."""
        if not self.radio_ranges:
            return alive
        keep = set(alive)
        radio = False
        for gi, radius in self.radio_ranges.items():
            gs = state.groups[gi]
            if gs is None:
                continue
            radio = True
            peers = [a for a in alive if self.layout.owner[a][0] == gi]
            if peers:
                xs = np.array([self.latest[a].x for a in peers])
                near = proximity.in_range(gs.x, xs, radius)
                keep -= {a for a, n in zip(peers, near) if not n}
        out = [a for a in alive if a in keep]
        if radio:
            self.in_range_count = len(out)
        return out

    def peer_rows(self, alive: Iterable[int]) -> dict[int, dict[int, wire.Row]]:
        """Group -> {group row: Row} of the ``alive`` peers' latest states, for each group
        needed: what every stage of a tick sees of them (``ensemble``)."""
        alive = set(alive)
        out: dict[int, dict[int, wire.Row]] = {}
        for gi in self.layout.groups_needed:
            g = self.model.groups[gi]
            out[gi] = {a - g.start: wire.Row((p := self.latest[a]).x, p.rot, p.v)
                       for a in g.indices if a in alive}
        return out

    def ensemble(self, request: Request, peers: dict[int, dict[int, wire.Row]]) -> Ensemble:
        """Frozen peers (``peer_rows``, found once a tick) + the local stage rows, per needed
        group, ``index`` = the rows present."""
        model = self.model
        out: list[SimpleNamespace | None] = []
        with_v = model.order == 2 and "v" in request.fields
        for gi in range(len(model.groups)):
            if gi not in peers:
                out.append(None)
                continue
            rows = peers[gi]
            own = len(self.layout.rows[gi]) > 0
            local = (self.layout.rows[gi], request.stage.groups[gi]) if own else None
            out.append(
                wire.assemble(self.grp, model.dim, rows, local, with_rot=own, with_v=with_v)
            )
        return tuple(out)


class RealtimeAgent(RuntimeParams, AgentBase):
    """Steps on a wall-clock timer (``rate`` Hz, ``time_scale`` simulated s per s) with the newest
    peer poses; starts now, on the runner's ``start <epoch>`` (start control) or at
    ``start_time``."""

    mode = wire.Mode.REALTIME

    def __init__(
        self, node: Node, resolved: ResolvedAgent, executor: Executor | None = None
    ) -> None:
        super().__init__(node, resolved, executor)
        self.clock = ClockOffsets(self.config.time_scale, self.config.clock_offset_warn)
        self.peers = PeerTable.of_agent(self, self.clock)
        # process CPU time (s) when the ticks began and ended
        self.cpu_span: tuple[float, float | None] | None = None
        self.served = 0.0  # monotonic time the agent node was last served (``_wait_tick``)
        self.watch_parameters()

    def rebuild_system(self) -> None:
        self.system = System(self.model, self.layout.rows)

    def record(self) -> wire.RunRecord:
        rec = super().record()
        rec.clock_offsets = self.clock.offsets()
        return rec

    def extra_diagnostics(self) -> dict[str, Any]:
        """Each peer's estimated clock offset (s, its clock ahead of ours); warns once per peer
        whose offset passes ``clock_offset_warn``."""
        for agent, offset in self.clock.over_threshold():
            self.node.get_logger().warning(
                f"agent {agent}: clock offset {offset:+.3f} s is past "
                f"{self.clock.threshold:g} s (estimated from its pose stamps)"
            )
        out: dict[str, Any] = {f"clock_offset_s: agent {a}": v
                               for a, v in sorted(self.clock.offsets().items())}
        if self.peers.in_range_count is not None:
            out["peers_in_range"] = self.peers.in_range_count
        return out

    def step_size(self) -> float:
        """Simulated seconds a tick (``rate`` may change while running)."""
        return self.config.time_scale / self.config.rate

    def time_split(self) -> dict[str, float]:
        """CPU milliseconds per tick of the whole process (the middleware's threads too), over
        the ticks so far."""
        if self.rounds == 0 or self.cpu_span is None:
            return {}
        start, end = self.cpu_span
        return {"cpu": ((end or time.process_time()) - start) / self.rounds * 1e3}

    def _start_epoch(self: AgentBase) -> float:
        """Wall-clock time of t = 0 ('start'): now, the runner's 'start', or 'start_time';
        from then on the start_time parameter holds it."""
        start = self.config.start
        last = 0.0
        while start == "control" and self.start_epoch is None and not self.stop_requested:
            self.spin_once(0.05)
            if time.monotonic() - last > 0.5:  # keep announcing the initial pose
                self.publish_state()
                self._maybe_diagnostics(force=True)  # the runner counts agents that are up
                last = time.monotonic()
        epoch = {"at": self.config.start_time, "control": self.start_epoch}.get(start or "now")
        epoch = time.time() if epoch is None else epoch
        self.config = replace(self.config, start_time=epoch)
        declare_resolved(self.node, SPEC["start_time"], epoch)
        return epoch

    def _wait_tick(self, next_tick: float, period: float) -> None:
        """Sleep until the tick is due, serving the agent node (control, services, parameters)
        every ``SERVE_PERIOD`` s, not at every tick: each spin rebuilds a wait set of all the
        node's entities, which at 20 Hz and more cost a tick as much as its step.  The peers'
        poses wait in their readers for ``PeerTable.active``."""
        while True:
            now = time.monotonic()
            left = next_tick - now
            if left <= 0 or self.stop_requested:
                break
            if now - self.served >= SERVE_PERIOD:
                self.spin_once(0.0)
                self.served = time.monotonic()
                continue
            time.sleep(min(left, self.served + SERVE_PERIOD - now))
        if time.monotonic() - next_tick > period:  # behind schedule: the CPU is short
            self.late_ticks += 1

    def loop(self) -> None:
        self.wait_for_discovery()
        self._resume()
        self.publish_state()
        start = self._start_epoch()
        self.clock.start(start)
        while time.time() < start and not self.stop_requested:  # the ensemble starts together
            self.spin_once(min(0.05, max(0.0, start - time.time())))
        method, h, period = self.numerics.method, self.numerics.dt, 1.0 / self.config.rate
        assert isinstance(method, Method) and h is not None  # distributed plans: fixed step
        next_tick = self._join_clock(start, period, h)
        t0 = time.monotonic()
        self.cpu_span = (time.process_time(), None)
        while self.state.t < self.scene.t_end - 1e-12 and not self.stop_requested:
            next_tick += period
            self._wait_tick(next_tick, period)
            if self.apply_runtime():  # kappa, gamma, rate set while running
                h, period = self.step_size(), 1.0 / self.config.rate
            t = self.state.t
            step = min(h, self.scene.t_end - t)  # the last tick ends the run at t_end exactly
            if self._held(t + step):
                continue
            alive = self.peers.in_range(self.peers.active(), self.state)
            heard = self.peers.peer_rows(alive)

            def answer(request: Request, stage: int,
                       heard: dict[int, dict[int, wire.Row]] = heard) -> Ensemble:
                return self.peers.ensemble(request, heard)

            self.state.coupling = None
            self.state = drive(method, self.system, self.state, step, answer)
            self.state.t = t + step
            self.checkpoint.write(self.steps, self.state.t, self.state)
            self.steps += 1
            self.rounds += 1
            self.round_time = time.monotonic() - t0
            self.publish_state()
        self.cpu_span = (self.cpu_span[0], time.process_time())

    def _resume(self) -> None:
        """Restarted: from the state of its last tick (what its peers last heard of it), on the
        ensemble's clock as any late joiner (``_join_clock``)."""
        found = self.checkpoint.read()
        if found is not None:
            self.state = found.state
            self.log.warning(f"restarted: resumes from its state at t = {found.t:.6g}")

    def release(self) -> None:
        """The peers' lean node (lifecycle cleanup)."""
        self.peers.destroy()
        super().release()

    def destroy(self) -> None:
        self.peers.destroy()
        super().destroy()

    def _held(self, t_next: float) -> bool:
        """Reset and pause (``control.AgentControl``): back to the initial state at the tick
        past the reset epoch; while paused, the state held and published at the tick's time.
        True if this tick does not step."""
        if self.control.take_reset(time.time()):
            self.state = local_state(self.scene, self.layout)
            self.log.info(f"reset: back to the initial state at t = {t_next:.4g}")
        if not self.paused:
            return False
        self.state.t = t_next
        self.publish_state()
        return True

    def _join_clock(self, start: float, period: float, h: float) -> float:
        """Set the initial simulated time of a realtime run; return the monotonic time of tick 0.

        Tick k is due at ``start + k * period`` on every agent, and an agent a little late (a
        loaded CPU) catches up tick by tick.  An agent (re)joining a running ensemble - later
        than the peer timeout - starts from its initial state on the ensemble's clock instead of
        replaying the past: the newest simulated time its peers publish, so that it agrees with
        an ensemble that runs behind the wall-clock schedule (a CPU short of the rate), or the
        wall-clock schedule when it hears no peer within the peer timeout.
        """
        behind = max(0.0, time.time() - start)
        if behind <= self.config.peer_timeout:
            self.state.t = 0.0
            return time.monotonic() - behind
        heard_by = time.monotonic() + self.config.peer_timeout
        while (
            self.peers.newest_time() is None
            and time.monotonic() < heard_by
            and not self.stop_requested
        ):
            self.spin_once(0.05)
        newest = self.peers.newest_time()
        skipped = int(round(newest / h)) if newest is not None else int(behind / period)
        self.state.t = skipped * h
        return (
            time.monotonic()
            if newest is not None
            else time.monotonic() - (behind - skipped * period)
        )
