"""Lockstep: agents advance in rounds and exchange exactly what the integrator's stages need.

Every stage of every step is one round: each process publishes its agents' stage values
and waits for every peer's of the same round, so the distributed trajectory equals the
centralised simulator's for the same method and step, to round-off (Theorems 4.1/4.2 are
then the simulator's).
"""

from __future__ import annotations

import time
from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass
from types import SimpleNamespace
from typing import TYPE_CHECKING, Any

from ...core.stepping.simulate import drive, step_grid
from ...core.stepping.solver import Method
from .. import wire
from ..wire.intake import RoundTimeout, lean_node
from .agent_base import AgentBase
from .stage_links import AgentLinks, BlockLinks, local_fields
from .state_stride import StateStride

if TYPE_CHECKING:
    from rclpy.executors import Executor
    from rclpy.node import Node

    from ...core.model import Request
    from ..config.resolve import ResolvedAgent
    from ..wire.intake import DropCounter, Layout

#: a round: (step, stage)
Round = tuple[int, int]
#: a stage index past any step's last
ROUND_MAX = 1 << 30
#: per group the arrays the core asks for (``wire.assemble``), None for groups not needed
Ensemble = tuple[SimpleNamespace | None, ...]

# A round that has waited this long re-sends this process's last two rounds of stage messages,
# and again each period after.  RELIABLE delivery repairs a lost datagram, but a sample can
# still vanish for good: a peer starved past its DDS lease is matched anew as a late joiner
# of a VOLATILE topic, and what was sent before the new match never reaches it.  Every
# process then waits for a present peer and the run stalls.  A peer is at most one round
# ahead or behind, so the last two rounds are all it can miss; receivers take a repeat of a
# round they already have as what it is (``repeats``), not as a drop.
RESEND_AFTER = 1.0  # s


@dataclass(frozen=True)
class Patience:
    """How a round waits for its peers, and what it keeps for one that falls behind."""

    stall_timeout: float = 300.0  # past round_timeout: how long a present, silent peer is awaited
    peers_restart: bool = False   # a peer that left is restarted by its runner: awaited like a
    #                               slow one (up to stall_timeout), not a failure at once
    keep_rounds: int = 2          # rounds of this process's messages kept for ``resend``


PATIENT = Patience()


class LockstepExchange:
    """Stage rounds: publish the local stage rows, wait for every peer's message of the same round.

    Runs on its own lean node and executor (``lean_node``); ``spin_once`` waits on nothing but
    the peers' stage topics, whose names the agent node (``resolver``) resolves.
    """

    def __init__(self, resolver: Node, layout: Layout, run_id: int, rot_tol: float,
                 drops: DropCounter, t_max: float | None, patience: Patience = PATIENT) -> None:
        self.node, self.executor = lean_node(
            resolver.get_name() + "_stages", resolver.get_namespace()
        )
        self.layout, self.run_id, self.drops = layout, int(run_id), drops
        self.model = layout.model
        self.grp = self.model.rotations
        self.rot_tol, self.t_max = rot_tol, t_max
        self.resends = 0  # rounds re-sent because a peer's message did not come
        self.repeats = 0  # peers' messages of rounds already taken (their resends)
        self.answered = (0, 0.0)  # repeats answered after the last round, and when
        self.taken: dict[int, Round] = {}  # peer -> the last round of it this process has taken
        # round -> {the first agent of a message: its rows}: a message of one peer or a block
        self.inbox: defaultdict[Round, dict[int, wire.StageRows]] = defaultdict(dict)
        self.heard: defaultdict[Round, set[int]] = defaultdict(set)  # round -> peers heard
        self.current: Round = (0, 0)
        self.assembled: Round = (-1, -1)  # the last round taken out of the inbox
        self.stop_step: int | None = None  # graph runs: the step after which every agent stops
        # the agent serves its control topic and answers this
        self.paused: Callable[[], bool] = lambda: False
        grp, dim = self.grp, self.model.dim
        self.links: AgentLinks | BlockLinks
        if layout.blocks:
            def decode_rows(msg: Any, block: int) -> tuple[wire.StageRows | None, str | None]:
                return wire.decode_block(msg, grp, dim, self.run_id, block, layout.k,
                                         rot_tol, t_max)

            self.links = BlockLinks(self.node, resolver, layout, decode_rows, self._take, drops,
                                    patience.keep_rounds)
        else:
            def decode(msg: Any, agent: int) -> tuple[wire.StageRows | None, str | None]:
                return wire.decode_agent_rows(msg, grp, dim, self.run_id, agent, rot_tol,
                                              t_max)

            self.links = AgentLinks(self.node, resolver, layout, decode, self._take, drops,
                                    patience.keep_rounds)
        self.pubs, self.writers = self.links.pubs, self.links.writers
        self.unheard = self.links.unheard()  # no process needs our rows: nothing to publish
        self.patience = patience
        self.publish_time = 0.0  # seconds spent publishing stages (for the diagnostics)
        self.wait_time = 0.0  # seconds spent waiting for (and taking) the peers' stages

    def _take(self, rows: wire.StageRows) -> None:
        """A peer's decoded stage message (its rows): into the inbox, unless its round is past.
        A message heard twice (a resend) is kept once: its first agent names it."""
        first, key = int(rows.agents[0]), (rows.step, rows.stage)
        if key < self.current or key <= self.assembled:
            if key <= self.taken.get(first, (-1, -1)):
                self.repeats += 1  # a resend of a round already taken: not a drop
            else:
                self.drops(f"agent {first}", "stale round (a stamp from the past)")
            return
        self.inbox[key][first] = rows
        self.heard[key].update(rows.agents.tolist())

    def resume_at(self, step: int) -> None:
        """A restarted process begins with step ``step``: the peers' resends of earlier rounds
        are repeats, not drops."""
        self.current = (step, 0)
        self.taken = {a: (step - 1, ROUND_MAX) for a in self.layout.peers}

    def matched(self) -> bool:
        """All peers' publishers matched, and all expected remote subscribers matched."""
        return self.links.matched()

    def missing_peers(self) -> list[int]:
        return self.links.missing_peers()

    def _stop_flags(self, stop_flag: bool) -> int:
        """Header flags: FLAG_STOP, on a graph with the agreed stop step in the bits above it."""
        if not self.layout.sparse:
            return wire.FLAG_STOP if stop_flag else 0
        return 0 if self.stop_step is None else wire.FLAG_STOP | (self.stop_step << 1)

    def _agree_stop(self, key: Round, stop_flag: bool) -> bool:
        """On a graph a stop spreads one hop per round: min-consensus on a step far enough
        ahead (n_agents + 1 steps) that every agent knows it before reaching it.

        True from that step on."""
        step = key[0]
        targets = [step + self.model.n_agents + 1] if stop_flag else []
        for rows in self.inbox[key].values():
            if rows.flags & wire.FLAG_STOP:
                targets.append(rows.flags >> 1)
        if self.stop_step is not None:
            targets.append(self.stop_step)
        self.stop_step = min(targets, default=None)
        return self.stop_step is not None and step >= self.stop_step

    def publish(self, step: int, stage: int, request: Request, stop_flag: bool) -> None:
        if self.unheard:
            return
        agents, fields = local_fields(self.grp, request, self.layout)
        flags = self._stop_flags(stop_flag)
        self.links.publish(self.run_id, step, stage, flags, request.stage.t, agents, fields)

    def resend(self, key: Round, waiting: list[int], waited: float) -> None:
        """Publish the kept rounds' messages again (see ``RESEND_AFTER``)."""
        self.resends += 1
        self.drops.logger.warning(
            f"round (step {key[0]}, stage {key[1]}): no message from agent(s) "
            f"{', '.join(map(str, waiting))} after {waited:.1f} s; re-sending this process's "
            f"last {self.links.keep} rounds ({self.resends} so far)",
            throttle_duration_sec=5.0,
        )
        self.links.resend()

    def spin_once(self, timeout: float) -> None:
        self.executor.spin_once(timeout_sec=timeout)

    def answer_replays(self, timeout: float) -> None:
        """After the last round, while the final poses are held: a peer's messages of rounds
        already taken come from a peer that replays them (one restarted after its last step,
        before the runner had its final state, resumes at that step from its checkpoint) and
        waits for ours.  Re-send the kept rounds, which hold that step, at most every
        ``RESEND_AFTER`` s while new repeats come."""
        self.executor.spin_once(timeout_sec=timeout)
        repeats, at = self.answered
        now = time.monotonic()
        if self.repeats > repeats and now - at >= RESEND_AFTER:
            self.resends += 1
            self.links.resend()
            self.answered = (self.repeats, now)

    def round(
        self, step: int, stage: int, request: Request, stop_flag: bool, timeout: float
    ) -> tuple[Ensemble, bool]:
        """Publish, wait, assemble: returns (ensemble, stop requested by anyone)."""
        key = (step, stage)
        self.current = key
        t0 = time.perf_counter()
        self.publish(step, stage, request, stop_flag)
        t1 = time.perf_counter()
        self.publish_time += t1 - t0
        heard = self.heard[key]
        waiting = [a for a in self.layout.peers if a not in heard]
        resend_at, paused_for = RESEND_AFTER, 0.0
        while waiting:
            waited = time.perf_counter() - t1
            if waited >= resend_at:
                resend_at = waited + RESEND_AFTER
                if self.paused():  # a paused ensemble's waits neither count nor re-send
                    paused_for += RESEND_AFTER
                else:
                    self.resend(key, waiting, waited)
            left = timeout - (waited - paused_for)
            if left <= 0:
                self._give_up_if_gone(key, timeout, waiting, waited - paused_for)
            wait = min(resend_at - waited, 0.5)
            self.executor.spin_once(timeout_sec=min(wait, left) if left > 0 else wait)
            waiting = [a for a in waiting if a not in heard]
        self.wait_time += time.perf_counter() - t1
        if self.layout.sparse:
            stop = self._agree_stop(key, stop_flag)
        else:
            stop = stop_flag or any(
                rows.flags & wire.FLAG_STOP for rows in self.inbox[key].values()
            )
        return self._assemble(key, request), stop

    def _give_up_if_gone(
        self, key: Round, timeout: float, waiting: list[int], waited: float
    ) -> None:
        """Past ``round_timeout``: fail if a peer we wait for has left (its writer is no longer
        matched: a crash, an exit, or a SIGKILL once its DDS lease ran out) and no runner
        restarts it (``Patience.peers_restart``), or if a peer has been silent for
        ``stall_timeout``.  A peer that is still there is slow, not gone (a
        loaded machine can starve one process for many seconds), so the round waits on."""
        gone = [a for a in waiting if self.writers[a].get_publisher_count() < 1]
        stall = self.patience.stall_timeout
        if (not gone or self.patience.peers_restart) and waited < stall:
            return
        why = (f"agent(s) {', '.join(map(str, gone))} left" if gone else
               f"present but silent for stall_timeout = {stall:g} s")
        raise RoundTimeout(
            f"lockstep round (step {key[0]}, stage {key[1]}) timed out after {timeout:g} s "
            f"waiting for agent(s) {', '.join(map(str, waiting))}; {why} "
            f"({waited:.1f} s in all)"
        )

    def _assemble(self, key: Round, request: Request) -> Ensemble:
        """Per group the peers' stage rows and the local ones (None for groups not needed),
        array by array (``wire.assemble_rows``); the round leaves the inbox."""
        model = self.model
        messages = self.inbox.pop(key, {})
        self.heard.pop(key, None)
        self.assembled = key
        out: list[SimpleNamespace | None] = []
        with_v = "v" in request.fields and model.order == 2
        for gi, g in enumerate(model.groups):
            if gi not in self.layout.groups_needed:
                out.append(None)
                continue
            own = gi in self.layout.local_groups  # other groups: only centroids are used (F-2)
            local = (self.layout.rows[gi], request.stage.groups[gi]) if own else None
            # on a graph only the in-neighbours' rows are present (``index`` names them)
            out.append(wire.assemble_rows(
                self.grp, model.dim, g.start, g.size, messages.values(), local, with_rot=own,
                with_v=with_v, full=not self.layout.sparse,
            ))
        for first in messages:  # a resend is told by its first agent (``_take``)
            self.taken[first] = key
        return tuple(out)

    def flush(self, timeout: float = 5.0) -> None:
        """Wait until every stage message this process sent has been acknowledged."""
        self.links.flush(timeout)

    def destroy(self) -> None:
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()


class LockstepAgent(AgentBase):
    """Rounds with the group's stages; the trajectory equals the centralised simulator's."""

    mode = wire.Mode.LOCKSTEP

    def __init__(
        self, node: Node, resolved: ResolvedAgent, executor: Executor | None = None
    ) -> None:
        super().__init__(node, resolved, executor)
        config = self.config
        projection = self.numerics.method.info.family == "projection"
        rot_tol = wire.PROJECTION_STAGE_TOL if projection else wire.ROTATION_TOL
        restarts = config.peers_restart
        # a restarted peer resumes at the start of a step: keep a step and two rounds for it
        keep = self.numerics.method.info.rounds + 2 if restarts else 2
        patience = Patience(config.stall_timeout, restarts, keep)
        self.exchange = LockstepExchange(
            node, self.layout, config.run_id, rot_tol, self.drops, self.scene.t_end, patience
        )
        self.exchange.paused = self._serve_control
        self.resumed_at: int | None = None  # the step this process resumed at, if restarted
        # the steps whose states go out on the run's exchange (the monitor's), at its pace
        self.state_stride = StateStride(config.exchange_rate)

    def _serve_control(self) -> bool:
        """Inside a long round wait: take control messages and service calls; paused?"""
        for _ in range(4):  # what is ready: control messages, service calls, parameters
            self.spin_once(0.0)
        return self.paused

    def time_split(self) -> dict[str, float]:
        ex, timed = self.exchange, self.rounds - self.untimed_rounds
        if timed <= 0:
            return {}
        pub, wait = ex.publish_time / timed * 1e3, ex.wait_time / timed * 1e3
        rest = max(0.0, self.round_time / timed * 1e3 - pub - wait)
        return {"publish": pub, "wait": wait, "other": rest}

    def stage_subscriptions(self) -> int:
        return len(list(self.exchange.node.subscriptions))

    def record(self) -> wire.RunRecord:
        rec = super().record()
        rec.resumed_at = self.resumed_at
        return rec

    def extra_diagnostics(self) -> dict[str, Any]:
        """Rounds re-sent for a peer whose message did not come, and peers' resends taken."""
        return {"stage_resends": self.exchange.resends, "stage_repeats": self.exchange.repeats}

    def _discover(self) -> None:
        ex = self.exchange

        def matched() -> bool:
            ex.spin_once(0.0)
            return ex.matched()

        self.wait_for_discovery(matched, ex.missing_peers)

    def loop(self) -> None:
        self._discover()
        first = self._resume()
        if first:  # its pose of that step is out already: the runner hears it is back
            self._maybe_diagnostics(force=True)
        else:
            self.publish_state()
        method, dt = self.numerics.method, self.numerics.dt
        assert isinstance(method, Method) and dt is not None  # distributed plans: fixed step
        grid = step_grid(self.scene.t_end, dt)
        timeout = self.config.round_timeout
        # matching is not simultaneous: a peer that matched us may still be matching others and
        # start later, and its lag reaches us through every peer that waits for it in the next
        # rounds: the first two steps (of a resumed process too) also allow discovery time
        first_wait = timeout + self.config.discovery_timeout
        start = last_spin = time.monotonic()
        prev = float(grid[first - 1]) if first else 0.0
        for k in range(first, len(grid)):
            t_next = grid[k]
            if self.checkpoint.enabled:  # the kept messages are copied only to be written
                self.checkpoint.write(k, prev, self.state, self.exchange.links.snapshot())
            stop = False

            def answer(request: Request, stage: int, k: int = k) -> Ensemble:
                nonlocal stop
                wait = first_wait if k <= first + 1 else timeout
                ensemble, stop_seen = self.exchange.round(
                    k, stage, request, self.stop_requested, wait
                )
                stop = stop or (request.boundary and stop_seen)
                self.rounds += 1
                if self.rounds == 1:  # it waited for the last peer to start: rates count after it
                    nonlocal start
                    start, self.untimed_rounds = time.monotonic(), 1
                    self.first_round_at = time.time()
                    self.exchange.publish_time = self.exchange.wait_time = 0.0
                return ensemble

            self.state = drive(method, self.system, self.state, t_next - prev, answer)
            self.state.t = prev = t_next
            self.steps += 1
            now = time.monotonic()
            self.round_time = now - start
            last = stop or k == len(grid) - 1
            self.publish_step(exchange=self.state_stride.due(self.steps, last))
            # the node's own entities (control topic, parameter services) cost a full wait-set
            # rebuild per spin: serve them a few times a second, not every step
            if now - last_spin > 0.1:
                self.spin_once(0.0)
                last_spin = now
            while self.paused and not self.stop_requested:  # no new round while paused
                self.spin_once(0.05)
                self.exchange.spin_once(0.05)  # the peers' stages of the next round wait here
            if stop:
                break

    def _resume(self) -> int:
        """The step to begin with: 0, or after a restart the step of this process's checkpoint,
        its state restored and the exchange set to that step's first round."""
        found = self.checkpoint.read()
        if found is None:
            return 0
        self.state, self.steps, self.resumed_at = found.state, found.step, found.step
        self.exchange.resume_at(found.step)
        self.exchange.links.restore(found.sent)
        self.log.warning(
            f"resumed at step {found.step} (t = {found.t:.6g}) from this process's checkpoint"
        )
        return found.step

    def settle(self) -> None:
        """Hold the final poses until the lead host says 'received': it then has every agent's
        final pose and the monitor has reported the final step, so every agent has ended its
        last round and no reader needs a message of ours.  Without that word (no runner, or its
        hold ran out) wait until our last stage and pose messages are acknowledged: a writer
        that exits takes unacknowledged samples along, and an acknowledgement comes only with
        the writer's next heartbeat, up to 3 s later."""
        self.hold_final_poses(lambda: self.exchange.answer_replays(0.02))
        if not self.control.final_received:
            self.exchange.flush()
            self.flush_poses()

    def release(self) -> None:
        """The exchange's lean node (lifecycle cleanup)."""
        self.exchange.destroy()
        super().release()

    def destroy(self) -> None:
        self.exchange.destroy()
        super().destroy()
