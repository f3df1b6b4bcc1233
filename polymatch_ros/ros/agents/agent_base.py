"""What every polytope agent shares, whatever its mode (``agent.py`` picks the mode's class).

The node lives in the ensemble's namespace (``__ns``, default ``/polymatch``) under the
name the remap rules give it (``__node``; the runner uses ``agent_<i>``); its topics are
relative (``wire.TOPICS``).  One class per mode: ``lockstep.LockstepAgent`` exchanges every
integrator stage so the trajectory equals ``polymatch simulate`` to round-off;
``realtime.RealtimeAgent`` steps on a wall-clock timer with the latest pose of each peer.
What both need is here: scene and layout, publishers, the control topic and services
(``control``), diagnostics, the run record, discovery.
"""

from __future__ import annotations

import resource
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from ...core.errors import ParameterError, PolymatchError
from ...core.model import GroupState, State, System
from ...core.stepping.simulate import prepare
from .. import wire
from ..config.configs import AgentConfig
from ..config.params import RUNTIME
from ..process.shell import NodeApp
from ..wire.checkpoint import CheckpointFile
from ..wire.control import AgentControl, describe_command, offer_agent_services, parse_command
from ..wire.intake import DropCounter, Layout
from .hosted import HostedAgents

if TYPE_CHECKING:
    from rclpy.executors import Executor
    from rclpy.node import Node
    from rclpy.publisher import Publisher

    from ...core.scenes.scene import Scene
    from ..config.resolve import ResolvedAgent


def local_state(scene: Scene, layout: Layout) -> State:
    grp = scene.model.rotations
    groups: list[GroupState | None] = []
    for gs, rows in zip(scene.initial.groups, layout.rows):
        assert gs is not None  # the scene's initial state has every group
        groups.append(
            GroupState(
                gs.x[rows].copy(),
                grp.take(gs.rot, rows),
                None if gs.v is None else gs.v[rows].copy(),
                None if gs.w is None else grp.algebra_take(gs.w, rows),
            )
        )
    return State(0.0, tuple(groups))


class AgentBase(NodeApp):
    """Scene, state and publishing of the agents one process hosts; ``run()`` -> exit code.

    Subclasses set ``mode`` and define ``loop()``.
    """

    mode: wire.Mode  # each mode's class names its mode
    config: AgentConfig  # the process's parameters, resolved (``resolve.resolve_agent``)

    def __init__(
        self, node: Node, resolved: ResolvedAgent, executor: Executor | None = None
    ) -> None:
        from rclpy.executors import SingleThreadedExecutor

        self.node, self.config = node, resolved.config
        self.created = time.monotonic()
        self.matched_after: float | None = None
        self.log = node.get_logger()
        if executor is None:  # a managed agent (``managed``) brings the one its node spins in
            executor = SingleThreadedExecutor()
            executor.add_node(node)
        self.executor = executor
        self._configure(resolved)
        self._make_publishers()

    def _configure(self, resolved: ResolvedAgent) -> None:
        """The scene and numerical plan ``resolve_agent`` loaded, laid out for this process."""
        scene, config = resolved.scene, resolved.config
        local = config.hosted
        bad = [a for a in local if not 0 <= a < scene.model.n_agents]
        if bad:
            raise ParameterError(
                f"parameter 'agents': agent {bad[0]} is not in the scene "
                f"(0..{scene.model.n_agents - 1})"
            )
        self.numerics = resolved.numerics
        self.scene = scene = prepare(scene, self.numerics, distributed=True)
        self.model = scene.model
        self.grp = self.model.rotations
        self.layout = Layout(self.model, local, config.agents_per_process)
        self.system = System(self.model, self.layout.rows)
        self.state = local_state(scene, self.layout)
        self.drops = DropCounter(self.log)
        # the state at each step's start: a restarted process resumes from it, and the runner
        # saves it when the run ends early (``checkpoint``)
        self.checkpoint = CheckpointFile(config.checkpoint or "", config.run_id)
        self.control = AgentControl(self.mode, self.on_pause)
        self.rounds = self.steps = self.late_ticks = 0
        self.round_time = 0.0  # wall seconds of the timed rounds (all but ``untimed_rounds``)
        self.untimed_rounds = 0  # lockstep: the first round, which waits for every peer's start
        self.first_round_at: float | None = None  # wall-clock time the first round completed
        self.finished = False

    def _make_publishers(self) -> None:
        node, dim, local = self.node, self.model.dim, self.layout.local
        self.hosted = self._host_agents()
        # packed processes (lockstep, realtime) send their agents' states in one message a block
        # and step (tick)
        self.exchange_blocks = self.layout.local_blocks() if (
            self.mode.packs and self.layout.blocks) else None
        # writers by agent, or by block: (key of the per-step topic, of the final one), indices
        keys, by = ("state", "final_state"), local
        if self.exchange_blocks is not None:
            keys, by = ("state_block", "final_state_block"), list(self.exchange_blocks)
        self.exchange_pubs = {i: wire.publisher(node, keys[0], dim, i) for i in by}
        self.final_exchange_pubs = {i: wire.publisher(node, keys[1], dim, i) for i in by}
        self.block_rows = self._block_rows()

        def on_own_node(key: str) -> dict[int, Publisher]:
            """The people's topic ``key`` of each local agent, on the agent's own node."""
            owner = self.hosted.nodes if self.hosted is not None else dict.fromkeys(local, node)
            return {a: wire.publisher(owner[a], key, dim, a, resolver=node) for a in local}

        self.pose_pubs, self.final_pubs = on_own_node("pose"), on_own_node("final_pose")
        second = self.model.order == 2
        self.twist_pubs = on_own_node("twist") if second else {}
        self.final_twist_pubs = on_own_node("final_twist") if second else {}
        self.diag_pub = wire.publisher(node, "diagnostics")
        self.status_pub = wire.publisher(node, "status")
        wire.subscription(node, "control", self._control)
        self.services = offer_agent_services(node, self.control, self.log)
        self._last_diag = 0.0

    def _host_agents(self) -> HostedAgents | None:
        """A node of its own for each agent of a process hosting several (``hosted``)."""
        local, level = self.layout.local, self.config.agent_nodes
        if len(local) < 2 or level == "none":
            return None
        runtime = RUNTIME if self.mode.ticks else ()
        return HostedAgents(self.node, local, self.config, self.control, runtime,
                            full=level == "full")

    # -- control: the ensemble's commands (control topic) and this process's services -------
    def _control(self, msg: Any) -> None:
        command = parse_command(msg)
        if command is None:
            self.drops("control", f"bad {describe_command(msg)}")
            return
        replays = self.control.replays
        _, message = self.control.command(*command)
        if self.control.replays > replays:
            self.log.warning(f"control {command[0]}: {message}")
        elif command[0] != "received":
            self.log.info(f"control {command[0]}: {message}")

    def on_pause(self, paused: bool) -> None:
        """Called when a pause or resume arrives (bridge agents command zero at once)."""

    @property
    def stop_requested(self) -> bool:
        return self.control.stop_requested

    @property
    def start_epoch(self) -> float | None:
        return self.control.start_epoch

    @property
    def paused(self) -> bool:
        return self.control.paused

    # -- publishing ------------------------------------------------------------------------------
    def publish_state(self, final: bool = False) -> None:
        """Publish every local agent's state on the run's exchange (peers, monitor) and its
        pose (and velocity) for people and tools; ``final``: on the latched final topics only
        (the last step's pose is already on the pose topic: once is not a repeat)."""
        if final:
            self._send_states(self.final_exchange_pubs)
            self._publish_rows(self.final_pubs, self.final_twist_pubs)
            self._maybe_diagnostics()
        else:
            self.publish_step()

    def publish_step(self, exchange: bool = True) -> None:
        """A step's states: on the run's exchange (unless not ``exchange``: lockstep sends them
        at the monitor's pace, ``state_stride``) and the pose topics.

        Per-step messages nobody subscribes to are not even built (the lockstep hot loop).
        """
        if exchange and any(p.get_subscription_count() for p in self.exchange_pubs.values()):
            self._send_states(self.exchange_pubs)
        if any(p.get_subscription_count() for p in self.pose_pubs.values()):
            self._publish_rows(self.pose_pubs, self.twist_pubs)
        self._maybe_diagnostics()

    def _publish_exchange(self, pubs: dict[int, Publisher]) -> None:
        """Every local agent's state with the run's id (``wire.exchange``) on ``pubs``."""
        state_msg = wire.message_type("state")
        st, run_id, grp = self.state, self.config.run_id, self.grp
        frame = self.config.frame_id
        for gi in self.layout.local_groups:
            gs, g = st.groups[gi], self.model.groups[gi]
            assert gs is not None  # the state holds every local group
            for r, row in enumerate(self.layout.rows[gi]):
                a = g.start + row
                v = w = None
                if gs.v is not None and gs.w is not None:  # second order: its velocities
                    v, w = gs.v[r], grp.algebra_take(gs.w, [r])
                pubs[a].publish(wire.encode_exchange(
                    state_msg(), grp, run_id, a, st.t, gs.x[r], grp.take(gs.rot, [r]), v, w,
                    frame))

    def _send_states(self, pubs: dict[int, Publisher]) -> None:
        """Every local agent's state on the run's exchange writers ``pubs``: a message per
        block (packed processes) or per agent."""
        if self.exchange_blocks is not None:
            self._publish_exchange_blocks(self.exchange_blocks, pubs)
        else:
            self._publish_exchange(pubs)

    def _block_rows(self) -> dict[int, np.ndarray]:
        """Packed processes: each block's agents as rows of the local groups' states laid end
        to end (what ``_publish_exchange_blocks`` sends), found once; else empty."""
        if self.exchange_blocks is None:
            return {}
        groups, layout = self.model.groups, self.layout
        agents = [groups[gi].start + r for gi in layout.local_groups for r in layout.rows[gi]]
        where = {a: r for r, a in enumerate(agents)}
        return {b: np.array([where[a] for a in members], dtype=int)
                for b, members in self.exchange_blocks.items()}

    def _publish_exchange_blocks(self, blocks: dict[int, list[int]],
                                 pubs: dict[int, Publisher]) -> None:
        """Every local agent's state with the run's id, one message per block on ``pubs``
        (``wire.encode_exchange_block``)."""
        block_msg = wire.message_type("state_block")
        st, grp, local = self.state, self.grp, self.layout.local_groups
        parts = [gs for gi in local if (gs := st.groups[gi]) is not None]  # every local group
        x = np.concatenate([gs.x for gs in parts])
        rot = grp.concat([gs.rot for gs in parts])
        v: np.ndarray | None = None
        w: np.ndarray | None = None
        vs = [gs.v for gs in parts if gs.v is not None]
        ws = [gs.w for gs in parts if gs.w is not None]
        if len(vs) == len(ws) == len(parts):  # second order
            v, w = np.concatenate(vs), grp.algebra_concat(ws)
        for b, members in blocks.items():
            rows = self.block_rows[b]
            msg = wire.encode_exchange_block(
                block_msg(), grp, self.config.run_id, b, st.t, members, x[rows],
                grp.take(rot, rows), None if v is None else v[rows],
                None if w is None else grp.algebra_take(w, rows), self.config.frame_id)
            pubs[b].publish(msg)

    def _publish_rows(
        self, pose_pubs: dict[int, Publisher], twist_pubs: dict[int, Publisher]
    ) -> None:
        st, frame = self.state, self.config.frame_id
        for gi in self.layout.local_groups:
            gs, g = st.groups[gi], self.model.groups[gi]
            assert gs is not None  # the state holds every local group
            for r, row in enumerate(self.layout.rows[gi]):
                a = g.start + row
                x = gs.x[r] + self.scene.origin
                pose_pubs[a].publish(
                    wire.pose_message(self.grp, st.t, x, self.grp.take(gs.rot, [r]), frame)
                )
                if self.model.order == 2:
                    assert gs.v is not None and gs.w is not None  # second order: velocities
                    w_one = self.grp.algebra_take(gs.w, [r])
                    twist_pubs[a].publish(
                        wire.twist_message(self.grp, st.t, gs.v[r], w_one, frame)
                    )

    def diagnostic_note(self) -> tuple[str, dict[str, Any]]:
        """(a note for the status message ('' or ending in '; '), extra {key: value})."""
        return "", {}

    def time_split(self) -> dict[str, float]:
        """Milliseconds per round publishing stages, waiting for peers, and everything else."""
        return {}

    def record(self) -> wire.RunRecord:
        """This process's run record (``wire.RunRecord``)."""
        timed = self.rounds - self.untimed_rounds
        rps = timed / self.round_time if self.round_time > 0 and timed > 0 else 0.0
        return wire.RunRecord(
            role="agent",
            mode=self.mode,
            t=float(self.state.t),
            agents=tuple(self.layout.local),
            finished=self.finished,
            steps=self.steps,
            rounds=self.rounds,
            rounds_per_second=rps,
            ms_per_round=self.time_split(),
            late_ticks=self.late_ticks,
            matched_after=self.matched_after,
            dropped=dict(self.drops.counts),
            peers=tuple(self.layout.peers),
            stage_subscriptions=self.stage_subscriptions(),
            n_agents=self.model.n_agents,
            node=self.node.get_fully_qualified_name(),
            run_id=int(self.config.run_id),
            first_round_at=self.first_round_at,
            max_rss_mb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
        )

    def stage_subscriptions(self) -> int:
        """Subscriptions to the peers' stage topics (lockstep only)."""
        return 0

    def flush_poses(self, timeout: float = 3.0) -> None:
        """Wait until the last poses reached every subscriber (the monitor, the runner)."""
        from rclpy.duration import Duration

        pubs = [self.pose_pubs, self.twist_pubs, self.final_pubs, self.final_twist_pubs,
                self.exchange_pubs, self.final_exchange_pubs]
        for pub in [p for group in pubs for p in group.values()] + [self.status_pub]:
            pub.wait_for_all_acked(Duration(seconds=timeout))

    def _maybe_diagnostics(self, force: bool = False) -> None:
        """Once a second: diagnostics for people and tools, the run record for the runner."""
        now = time.monotonic()
        if not force and now - self._last_diag < 1.0:
            return
        self._last_diag = now
        from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

        rec = self.record()
        self.status_pub.publish(rec.to_msg())
        status = DiagnosticStatus(
            name=f"polymatch{self.node.get_fully_qualified_name()}",
            hardware_id=self.node.get_fully_qualified_name(),
        )
        note, extra = self.diagnostic_note()
        fine = self.drops.total == 0 and not note
        status.level = DiagnosticStatus.OK if fine else DiagnosticStatus.WARN
        status.message = f"{self.mode}: t = {self.state.t:.4g}; {note}{self.drops.summary()}"
        vals = {
            "t": rec.t,
            "steps": rec.steps,
            "rounds": rec.rounds,
            "rounds_per_second": rec.rounds_per_second,
            "dropped": self.drops.total,
        }
        vals.update({f"{k}_ms_per_round": v for k, v in rec.ms_per_round.items()})
        vals.update({f"dropped: {k}": v for k, v in self.drops.counts.items()})
        vals.update(extra)
        vals.update(self.extra_diagnostics())
        status.values = [
            KeyValue(key=k, value=f"{v:.6g}" if isinstance(v, float) else str(v))
            for k, v in vals.items()
        ]
        arr = DiagnosticArray(status=[status])
        arr.header.stamp = self.node.get_clock().now().to_msg()
        self.diag_pub.publish(arr)

    def extra_diagnostics(self) -> dict[str, Any]:
        """{key: value} a mode adds to the diagnostics (realtime: the peers' clock offsets)."""
        return {}

    # -- running ---------------------------------------------------------------------------------
    def spin_once(self, timeout: float) -> None:
        self.executor.spin_once(timeout_sec=timeout)

    def wait_for_discovery(self, peers_matched: Callable[[], bool] | None = None,
                           missing: Callable[[], list[int]] | None = None) -> None:
        """Wait until ``peers_matched()``, pose_subscribers readers on every pose topic and
        exchange_subscribers on every exchange topic."""
        deadline = time.monotonic() + self.config.discovery_timeout
        wants = ((self.pose_pubs, self.config.pose_subscribers),
                 (self.exchange_pubs, self.config.exchange_subscribers))
        while True:
            peers_ok = peers_matched is None or peers_matched()
            if peers_ok and all(
                p.get_subscription_count() >= want for pubs, want in wants for p in pubs.values()
            ):
                self.matched_after = time.monotonic() - self.created
                return
            if time.monotonic() > deadline:
                gone = missing() if missing is not None else []
                what = f"agent(s) {', '.join(map(str, gone))}" if gone else "all subscribers"
                raise PolymatchError(
                    f"discovery timed out after {self.config.discovery_timeout:g} s "
                    f"waiting for {what}"
                )
            self.spin_once(0.05)

    def loop(self) -> None:
        raise NotImplementedError

    def run(self) -> int:
        self.loop()
        self.publish_state(final=True)
        self.finished = True
        self._maybe_diagnostics(force=True)
        self.settle()
        return 0

    def settle(self) -> None:
        """After the final pose: until its readers have it (and the lead host said so)."""
        self.flush_poses()
        self.hold_final_poses()

    def hold_final_poses(self, meanwhile: Callable[[], None] | None = None) -> None:
        """On a host without the summary: keep the latched final poses alive (this process)
        until the host with it says 'received', at most ``hold_final`` s, calling ``meanwhile``
        between spins.  Its runner may match our final-pose writers only after we published: a
        writer that ended by then is gone with its sample."""
        deadline = time.monotonic() + self.config.hold_final
        while not self.control.final_received and time.monotonic() < deadline:
            self.spin_once(0.05)
            if meanwhile is not None:
                meanwhile()

    def final_record(self) -> wire.RunRecord | None:
        return self.record() if self.finished else None

    def release(self) -> None:
        """What the agent built beside its node (lifecycle cleanup): its checkpoint's files,
        its agents' own nodes."""
        self.checkpoint.close()
        self._end_hosted()

    def destroy(self) -> None:
        self._end_hosted()
        super().destroy()

    def _end_hosted(self) -> None:
        hosted: HostedAgents | None = getattr(self, "hosted", None)  # None: configure failed
        if hosted is not None:
            hosted.destroy()
            self.hosted = None
