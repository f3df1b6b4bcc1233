"""The monitor: hears every agent's pose and publishes the ensemble's diameters.

It reads the run's states (``agent_<i>/state``, ``polymatch_interfaces/msg/AgentState``,
``wire.exchange``), whose messages carry the run's id: a pose published on ``agent_<i>/pose``
by anything else does not reach it.

    ros2 run polymatch_ros monitor --ros-args -r __ns:=/polymatch -r __node:=monitor \\
        -p scene:=config/congruent_triangles.yaml
    ros2 topic echo /polymatch/diameter

Publishes (in the ensemble's namespace, default ``/polymatch``; see ``wire.TOPICS``):
  diameter            std_msgs/Float64  the paper's matching diameter max_{i,j,a} |x^i_a - x^j_a|
                                        (max over groups; similar groups at their mean scale)
  diameter/centroid   std_msgs/Float64  max_{i,j} |xbar_i - xbar_j| (max over groups)
  diameter/rotation   std_msgs/Float64  max_{i,j} |O_i - O_j|_F (max over groups)
  status              polymatch_interfaces/RunRecord  its run record (``wire.RunRecord``),
                                        latched
  certificate         diagnostic_msgs/DiagnosticStatus  whether matching is guaranteed and by
                                        when (``core.certificate``), latched; granted once, in
                                        lockstep, and never withdrawn
  /diagnostics        diagnostic_msgs/DiagnosticArray: per-group diameters, energy,
                      orthogonality defect, agents heard, dropped messages; per proximity
                      graph its components among the agents heard and since when
                      (``component_statuses``)
  markers             visualization_msgs/MarkerArray: each polytope's edges (LINE_LIST),
                      one colour per group, lifetime = peer_timeout so silent agents fade
  start, stop, reset  std_srvs/Trigger  the ensemble's services (``control``), broadcast
  pause               std_srvs/SetBool  to every agent on the control topic
  match               polymatch_interfaces/action/Match  a goal until the diameter is below a
                                        tolerance, with feedback at each report; its cancel
                                        stops the ensemble (``match_action``)
  /clock              rosgraph_msgs/Clock  lockstep: the simulated time of the latest step
                                        every agent completed, ``report_rate`` times a
                                        second (``sim_clock``), for use_sim_time tools
In lockstep it collects the steps' states the agents send at its pace (``exchange_rate``,
``state_stride``) and reports, at most ``report_rate`` times a second, the latest simulated time
that every agent's state has reached (its loop, at that rate, takes the states that came since
its last report and publishes it; packed processes' block messages are held undecoded by step,
and only the step a report shows is decoded, ``held_steps``); in realtime at ``rate`` Hz from
the latest poses, taken only then.  Either way its reports take at most ``REPORT_CPU_SHARE``
of a core: where one costs more (a large ensemble), the reports come less often, and still
once a second at the least (``quiet_after``).
It ends on SIGINT or SIGTERM (exit 0), in lockstep after one more report of the latest step
completed, and never in the middle of a report.
The headline topics are RELIABLE + TRANSIENT_LOCAL (depth 1): a late `ros2 topic echo`
still gets the last value.
"""

from __future__ import annotations

import signal
import sys
import time
from collections.abc import Callable, Mapping
from dataclasses import replace
from types import FrameType
from typing import TYPE_CHECKING, Any

import numpy as np

from ...core.certificate import CertificateKeeper
from ...core.metrics import ensemble_metrics
from ...core.model import GroupState, State
from ...core.proximity import ComponentTracker
from .. import wire
from ..config.configs import MonitorConfig, given_config, pin_config
from ..config.resolve import resolve_monitor
from ..process.shell import NodeApp, ros_main
from ..wire.control import EnsembleControl
from ..wire.intake import DropCounter, LeanReaders, received_at
from .held_steps import Held, HeldSteps
from .match_action import MatchServer
from .monitor_output import certificate_status, diagnostics, markers
from .sim_clock import SimClock

if TYPE_CHECKING:
    from rclpy.node import Node

    from ...core.metrics import EnsembleMetrics
    from ...core.model import Model
    from ...core.scenes.scene import Scene
    from ..wire.intake import MessageInfo

#: how long the monitor waits for its report topics' readers (``report_readers``); the
#: agents' discovery timeout, for which they wait for the monitor, is longer
REPORT_READERS_SECONDS = 20.0
#: an agent's velocities as heard: (v, W as one algebra row)
Velocity = tuple[np.ndarray, np.ndarray]
#: the share of a core the reports may take: a report that costs c s of CPU is followed by the
#: next one no sooner than c / REPORT_CPU_SHARE s later (a thousand agents: a report or two a
#: second), so that watching an ensemble leaves the agents the machine
REPORT_CPU_SHARE = 0.02
#: the longest the reports stay quiet after a costly one: a report a second at the least (a
#: first report that loads what it needs, scipy's graph routines for a proximity graph, or a
#: thousand agents, would otherwise hold the next one for seconds)
MOST_QUIET_SECONDS = 1.0


class MonitorNode(NodeApp):
    def __init__(self, node: Node, config: MonitorConfig, scene: Scene) -> None:
        from rclpy.executors import SingleThreadedExecutor

        self.node, self.config = node, config
        self.log = node.get_logger()
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(node)
        self.scene = scene  # loaded once, by ``resolve_monitor``
        self.model = self.scene.model
        self.grp = self.model.rotations
        self.n = self.model.n_agents
        self.lockstep = wire.mode_of(config.mode).exact
        self.drops = DropCounter(self.log)
        self.repeats = 0  # poses heard again at a stamp already heard: not a drop
        self.latest: dict[int, tuple[int, wire.Row, float]] = {}  # agent -> (t key, Row, heard)
        self.velocity: dict[int, tuple[int, np.ndarray, np.ndarray]] = {}  # agent -> (t key, v, w)
        self.pending: dict[int, dict[int, wire.Row]] = {}  # time key -> {agent: Row} (lockstep)
        self.pending_v: dict[int, dict[int, Velocity]] = {}
        self.completed = -1  # lockstep: the latest stamp every agent (and velocity) reached
        # lockstep: (t, rows, velocities) of it until it is reported
        self.unreported: tuple[float, dict[int, wire.Row], dict[int, Velocity]] | None = None
        # lockstep blocks: (t, messages) of the completed step, decoded when it is reported
        self.unreported_held: tuple[float, list[Held]] | None = None
        # (t, metrics, agents heard) of the last report
        self.last: tuple[float, EnsembleMetrics, int] | None = None
        self.reports = 0
        self.stopping = False  # SIGINT or SIGTERM came: end after the report under way
        self.certificate = CertificateKeeper(self.scene.tolerance)
        self.components = ComponentTracker()  # proximity graphs: who hears whom, since when
        if self.lockstep:
            # the certificate's root finder (scipy.optimize: most of a second to load) is loaded
            # before the agents start, which wait for this node's readers, not in the first
            # report, which would hold the report loop (and /clock) while the rounds run
            import scipy.optimize  # noqa: F401
        self._wire_up()
        rate = config.report_rate if self.lockstep else config.rate
        self.report_period = 1.0 / rate
        self.report_due: Callable[[], None] = (
            self._report_completed if self.lockstep else self._report_latest
        )

    def _wire_up(self) -> None:
        """Readers of every agent's state on the run's exchange (``wire.exchange``: pose and
        velocities with the run's id; a reader per agent, or per block where packed lockstep
        processes send their agents' states together); the headline, diagnostics, status and
        marker writers; the ensemble's services.

        The readers live on a lean node of their own (``exchange.LeanReaders``), and each report
        takes what they hold first (``_drain``), so the poses do not wake the monitor between
        reports: in realtime each reader keeps an agent's newest pose (depth 1); in lockstep
        the poses of the steps since the last report (RELIABLE, depth 100), every one of
        which is taken, to complete every step."""
        node, dim = self.node, self.model.dim
        self.pub = {
            key: wire.publisher(node, key)
            for key in ("diameter", "diameter_centroid", "diameter_rotation")
        }
        self.diag_pub = wire.publisher(node, "diagnostics")
        self.status_pub = wire.publisher(node, "status")
        self.cert_pub = wire.publisher(node, "certificate")
        self.marker_pub = wire.publisher(node, "markers") if self.config.markers else None
        self._wait_for_report_readers()
        self.readers = LeanReaders(node, "_poses")
        k = self.config.agents_per_process
        # lockstep blocks: held by step, decoded only when reported (``held_steps``)
        self.held = HeldSteps(self.n, k, self.config.run_id, self.scene.t_end, self.grp,
                              dim) if self.lockstep and k > 1 else None
        if k > 1:  # packed processes: a message per block and step (tick)
            for b in range(-(-self.n // k)):
                receive = self._block_holder(b) if self.held else self._block_receiver(b, k)
                self.readers.subscribe("state_block", receive, dim, b, self.config.mode)
        else:
            for a in range(self.n):
                self.readers.subscribe("state", self._receiver(a), dim, a,
                                       self.config.mode)
        self.control = EnsembleControl(node, self.config.mode)
        self.match = MatchServer(node, self.scene.tolerance, self.n, self.control)
        self.clock = SimClock(node) if self.lockstep else None  # /clock: the completed step's

    def _wait_for_report_readers(self) -> None:
        """Until ``report_readers`` readers matched every report writer (at most
        ``REPORT_READERS_SECONDS``, then a warning): only then are the pose readers created,
        and the agents, which wait for them (``pose_subscribers``), start.  So a run's recorder
        hears the first report too: the writers' and readers' endpoints are matched pair by
        pair, and a short run may report only once."""
        want = self.config.report_readers
        writers = [*self.pub.values(), self.diag_pub, self.status_pub, self.cert_pub]
        writers += [self.marker_pub] if self.marker_pub is not None else []
        deadline = time.monotonic() + REPORT_READERS_SECONDS
        while any(w.get_subscription_count() < want for w in writers):
            if time.monotonic() > deadline:
                self.log.warning(f"reporting although not every report topic has "
                                 f"{want} reader(s) after {REPORT_READERS_SECONDS:g} s")
                return
            time.sleep(0.02)

    def _fresh(self, agent: int, key: int, pending: Mapping[int, Mapping[int, Any]]) -> bool:
        """Lockstep: True if this stamp is still to be completed.  The same stamp heard again
        (an agent's initial pose re-announced, a repeated publish) is expected traffic, not a
        drop; a stamp older than the last completed one is a stale message, dropped and counted."""
        if key > self.completed and agent not in pending.get(key, {}):
            return True
        if key >= self.completed:
            self.repeats += 1
        else:
            self.drops(f"agent {agent}", "stale pose (a stamp from the past)")
        return False

    def _receiver(self, agent: int) -> Callable[[Any, MessageInfo], None]:
        """The callback of one agent's exchange topic (``wire.exchange``: only this run's
        messages are read, anything else is dropped and counted)."""
        run_id = self.config.run_id

        def receive(msg: Any, info: MessageInfo) -> None:
            got, reason = wire.decode_exchange(msg, self.grp, self.model.dim, run_id, agent,
                                               self.scene.t_end)
            if got is None:
                self.drops(f"agent {agent}", reason)  # type: ignore[arg-type]  # with None
                return
            if self._take(agent, got, received_at(info)[1]):
                self._collect_completed()

        return receive

    def _block_receiver(self, block: int, k: int) -> Callable[[Any, MessageInfo], None]:
        """The callback of one block's exchange topic (K agents per process): each
        row as one agent's message; a malformed row drops the whole message."""
        run_id = self.config.run_id

        def receive(msg: Any, info: MessageInfo) -> None:
            got, reason = wire.decode_exchange_block(msg, self.grp, self.model.dim, run_id,
                                                     block, k, self.scene.t_end)
            if got is None:
                self.drops(f"block {block}", reason)  # type: ignore[arg-type]  # with None
                return
            heard = received_at(info)[1]  # a list, not a generator: every row is taken
            if any([self._take(agent, motion, heard) for agent, motion in got]):
                self._collect_completed()

        return receive

    def _block_holder(self, block: int) -> Callable[[Any, MessageInfo], None]:
        """Lockstep, the callback of one block's exchange topic: the message held undecoded
        under its step (``HeldSteps.hold``); anything of another run, or malformed, dropped and
        counted."""
        assert self.held is not None

        def receive(msg: Any, info: MessageInfo) -> None:
            assert self.held is not None
            why = self.held.hold(block, msg, received_at(info)[1], self.completed)
            if why == "repeat":
                self.repeats += 1
            elif why == "stale":
                self.drops(f"block {block}", "stale pose (a stamp from the past)")
            elif why is not None:
                self.drops(f"block {block}", why)

        return receive

    def _complete_held(self) -> None:
        """Lockstep blocks: the newest step held whole becomes the completed one; its messages
        wait undecoded in ``unreported_held`` for the next report, earlier ones are dropped."""
        key = self.held.newest_complete() if self.held is not None else None
        if key is None or self.held is None:
            return
        self.completed = key
        self.unreported_held = (key * 1e-9, self.held.take(key))
        self.unreported = None

    def _decode_held(self) -> None:
        """Decode the held step (``unreported_held``) into ``unreported`` (rows, velocities);
        a message the decoder refuses is dropped and counted, and the step not reported."""
        if self.unreported_held is None:
            return
        t, held = self.unreported_held
        self.unreported_held = None
        rows: dict[int, wire.Row] = {}
        vel: dict[int, Velocity] = {}
        k = self.config.agents_per_process
        for block, msg, _ in held:
            got, reason = wire.decode_exchange_block(msg, self.grp, self.model.dim,
                                                     self.config.run_id, block, k,
                                                     self.scene.t_end)
            if got is None:
                self.drops(f"block {block}", reason)  # type: ignore[arg-type]  # with None
                return
            for agent, motion in got:
                rows[agent] = wire.Row(motion.x, motion.rot)
                if motion.v is not None and motion.w is not None:
                    vel[agent] = (motion.v, motion.w)
        if len(rows) == self.n:
            self.unreported = (t, rows, vel)

    def _take(self, agent: int, got: wire.Motion, heard: float) -> bool:
        """One agent's state, heard at monotonic time ``heard``: its latest, and in lockstep
        the pending report of its stamp (a Row, and in second order the velocities (v, W)).
        True if it is pending (a step still to complete)."""
        row = wire.Row(got.x, got.rot)
        self.latest[agent] = (got.key, row, heard)
        velocity: Velocity | None = None
        if self.model.order == 2 and got.v is not None and got.w is not None:  # decoded together
            velocity = (got.v, got.w)
            self.velocity[agent] = (got.key, *velocity)
        if not (self.lockstep and self._fresh(agent, got.key, self.pending)):
            return False
        self.pending.setdefault(got.key, {})[agent] = row
        if velocity is not None:
            self.pending_v.setdefault(got.key, {})[agent] = velocity
        return True

    # -- reporting --------------------------------------------------------------------------
    def _state_from(
        self, rows: Mapping[int, wire.Row], velocities: Mapping[int, Velocity]
    ) -> tuple[Model, State, list[int]]:
        """The agents heard: (model of the groups present, their State, the group indices);
        with every agent heard, the scene's own model."""
        groups: list[GroupState | None] = []
        sub_groups, keep = [], []
        for gi, g in enumerate(self.model.groups):
            present = {a - g.start: rows[a] for a in g.indices if a in rows}
            if not present:
                continue
            with_v = self.model.order == 2 and all(a + g.start in velocities for a in present)
            if with_v:
                for r, rec in present.items():
                    rec.v, rec.w = velocities[r + g.start]
            e = wire.assemble(self.grp, self.model.dim, present, with_v=with_v, with_w=with_v)
            groups.append(GroupState(e.x, e.rot, e.v, e.w))
            scales = None if g.scales is None else g.scales[e.index]
            sub_groups.append(replace(g, size=len(present), scales=scales))
            keep.append(gi)
        state = State(0.0, tuple(groups))
        if len(rows) == self.n:
            return self.model, state, keep
        return replace(self.model, groups=tuple(sub_groups)), state, keep

    def _collect_completed(self) -> None:
        """Lockstep: advance to the latest simulated time all agents (and velocities) have
        reached; its poses wait in ``unreported`` for the next report, earlier ones are
        superseded unreported.  An earlier time still incomplete is passed over: each agent
        publishes its steps in order, so it lacks a message that will not come (a monitor
        restarted mid-step heard only the rest of it)."""
        need_v = self.model.order == 2
        for key in sorted(self.pending):
            rows = self.pending[key]
            if len(rows) < self.n or (need_v and len(self.pending_v.get(key, {})) < self.n):
                continue
            vel = self.pending_v.pop(key, {})
            del self.pending[key]
            self.completed = key
            self.unreported = (key * 1e-9, rows, vel)
        for pending in (self.pending, self.pending_v):
            for key in [k for k in pending if k <= self.completed]:
                del pending[key]

    def _follow(self) -> None:
        """Lockstep, every ``1 / report_rate`` s whether or not a report is due: take the states
        that came, and advance ``/clock`` to the latest step every agent has completed.  The
        clock so keeps its pace when the reports are spaced out (``REPORT_CPU_SHARE``)."""
        self._drain()
        self._complete_held()
        if self.clock is not None and self.completed >= 0:
            self.clock.advance(self.completed)

    def _report_completed(self) -> None:
        """Lockstep: publish the latest completed time if it is new."""
        self._follow()
        self._decode_held()
        if self.unreported is not None:
            t, rows, vel = self.unreported
            self.unreported = None
            self._publish(t, rows, vel)

    def _drain(self) -> None:
        """Take the poses and twists the readers hold (lockstep: up to their depth, 100 each)."""
        self.readers.drain(per_reader=200)

    def _report_latest(self) -> None:
        """Realtime, at ``rate`` Hz: the metrics of the newest pose of every agent heard within
        ``peer_timeout``."""
        self._drain()
        now = time.monotonic()
        alive = [a for a, v in self.latest.items() if now - v[2] <= self.config.peer_timeout]
        if not alive:
            return
        rows = {a: wire.Row(self.latest[a][1].x, self.latest[a][1].rot) for a in alive}
        vel = {a: self.velocity[a][1:] for a in alive if a in self.velocity}
        self._publish(max(self.latest[a][0] for a in alive) * 1e-9, rows, vel)

    def _evaluate(
        self, t: float, rows: Mapping[int, wire.Row], velocities: Mapping[int, Velocity]
    ) -> tuple[EnsembleMetrics, list[int]]:
        """The metrics of the agents heard (Prop 2.1/2.2 quantities); they become ``last``."""
        model, state, keep = self._state_from(rows, velocities)
        met = ensemble_metrics(model, state)
        self.last = (t, met, len(rows))
        return met, keep

    def _publish(
        self, t: float, rows: Mapping[int, wire.Row], velocities: Mapping[int, Velocity]
    ) -> None:
        from std_msgs.msg import Float64

        met, keep = self._evaluate(t, rows, velocities)
        statuses = component_statuses(self, t, rows)
        self.reports += 1
        for key, value in (
            ("diameter", met.diameter),
            ("diameter_centroid", max(g.centroid_diameter for g in met.groups)),
            ("diameter_rotation", max(g.rotation_diameter for g in met.groups)),
        ):
            self.pub[key].publish(Float64(data=float(value)))
        # diagnostics and markers are volatile: built only for readers that are there
        if self.diag_pub.get_subscription_count():
            arr = diagnostics(self, t, met, keep, len(rows))
            arr.status.extend(statuses)
            self.diag_pub.publish(arr)
        self.status_pub.publish(self.record().to_msg())
        self._certify(t, rows, velocities, met.diameter)
        self.match.report(t, met, len(rows), self.certificate)
        if self.marker_pub is not None and self.marker_pub.get_subscription_count():
            self.marker_pub.publish(markers(self, {a: (r.x, r.rot) for a, r in rows.items()}))

    def _certify(
        self, t: float, rows: Mapping[int, wire.Row], velocities: Mapping[int, Velocity],
        diameter: float,
    ) -> None:
        """Publish the certificate when it is news (``CertificateKeeper.observe``): evaluated on
        the state of every agent at one step (lockstep) until granted, then kept; a realtime
        state mixes poses of different ticks coupled through delays, which no theorem covers."""
        keeper = self.certificate
        if not self.lockstep:
            news = keeper.refuse(t, "realtime: the agents couple through delayed poses, which "
                                    "the theorems do not cover (lockstep runs are certified)")
        elif len(rows) < self.n and not keeper.granted:
            news = keeper.refuse(t, f"{len(rows)}/{self.n} agents heard")
        elif keeper.granted:
            news = keeper.observe(self.model, State(t, ()), diameter)
        else:
            model, state, _ = self._state_from(rows, velocities)
            news = keeper.observe(model, State(t, state.groups), diameter)
        if news:
            self.cert_pub.publish(certificate_status(self, keeper))

    def record(self) -> wire.RunRecord:
        t, met, heard = self.last if self.last is not None else (0.0, None, 0)
        return wire.RunRecord(
            role="monitor",
            mode=self.config.mode,
            t=float(t),
            diameter=None if met is None else met.diameter,
            agents_heard=heard,
            reports=self.reports,
            dropped=dict(self.drops.counts),
            run_id=int(self.config.run_id),
        )

    def run(self) -> int:
        """Serve the node (services, control) and report every ``report_period`` s, until
        SIGINT or SIGTERM (the monitor's normal end); then the latest completed step is
        reported (lockstep), so the last report is the final step's.

        The reports run here, not in a timer callback: a Ctrl-C that lands inside a callback
        leaves rclpy's task holding the timer, and destroying the node then once crashed the
        process (SIGSEGV).  The signals only set a flag: one landing in the middle of a report
        (the first one evaluates the certificate, which takes a while) once cut it between
        the diameters and the certificate and markers, and a recording lacked them."""
        for sig in (signal.SIGINT, signal.SIGTERM):  # after rclpy's: the end is ours
            signal.signal(sig, self._stop)
        due = time.monotonic() + self.report_period
        quiet_until = 0.0  # no report before (the reports' share of a core)
        while not self.stopping:
            self.executor.spin_once(timeout_sec=min(0.1, max(0.0, due - time.monotonic())))
            now = time.monotonic()
            if now >= due:
                due += self.report_period
                if due <= now:  # behind (a loaded machine): the next one a period from now
                    due = now + self.report_period
                cpu = time.thread_time()
                if now >= quiet_until:
                    self.report_due()
                elif self.lockstep:  # no report: the states still taken, /clock advanced
                    self._follow()
                quiet_until = quiet_after(quiet_until, now, time.thread_time() - cpu)
        if self.lockstep:
            self._report_completed()
        self.match.close(self.executor)  # open goals end; their results go out
        return 0

    def _stop(self, sig: int, frame: FrameType | None) -> None:
        self.stopping = True

    def destroy(self) -> None:
        self.readers.destroy()
        self.match.destroy()
        super().destroy()

    def final_record(self) -> wire.RunRecord | None:
        self._decode_held()
        if self.unreported is not None:  # completed after the last tick: the record is exact
            self._evaluate(*self.unreported)
            self.unreported = None
        if self.last is None:
            return None
        rec = self.record()
        rec.finished = True
        return rec


def quiet_after(quiet_until: float, now: float, spent: float) -> float:
    """Until when the reports stay quiet after one that took ``spent`` s of CPU at ``now``: at
    most ``REPORT_CPU_SHARE`` of a core, so ``spent / REPORT_CPU_SHARE`` s, but never more than
    ``MOST_QUIET_SECONDS`` (nor earlier than ``quiet_until`` already said)."""
    return max(quiet_until, now + min(spent / REPORT_CPU_SHARE, MOST_QUIET_SECONDS))


def component_statuses(mon: MonitorNode, t: float, rows: Mapping[int, wire.Row]) -> list[Any]:
    """One DiagnosticStatus per proximity-graph group: the components of its graph among the
    agents heard (WARN when more than one), since when (``core.proximity.ComponentTracker``)."""
    radios = [g for g in mon.model.groups if g.graph is not None and g.graph.dynamic]
    if not radios:
        return []
    from diagnostic_msgs.msg import DiagnosticStatus, KeyValue

    out = []
    for g in radios:
        assert g.graph is not None  # a proximity graph
        agents = [a for a in g.indices if a in rows]
        if not agents:
            continue
        x = np.array([rows[a].x for a in agents])
        now = mon.components.update(t, g.name, g.graph.radius, agents, x)
        values: dict[str, Any] = {"components": len(now.parts), "since": now.since,
                                  "radius": g.graph.radius}
        values.update({f"component {c}": " ".join(map(str, p)) for c, p in enumerate(now.parts)})
        out.append(DiagnosticStatus(
            name=f"polymatch/{mon.node.get_namespace().strip('/')}/components/{g.name}",
            hardware_id=g.name, message=now.describe(),
            level=DiagnosticStatus.WARN if now.split else DiagnosticStatus.OK,
            values=[KeyValue(key=k, value=str(v)) for k, v in values.items()]))
    return out


def make_monitor(argv: list[str] | None = None) -> MonitorNode:
    from rclpy.node import Node

    node = Node("monitor", namespace=wire.namespace(wire.DEFAULT_ENSEMBLE))
    config, scene = resolve_monitor(given_config(node, MonitorConfig))
    pin_config(node, config)
    return MonitorNode(node, config, scene)


def main(args: list[str] | None = None) -> int:
    # the monitor runs until it is stopped: Ctrl-C is its normal end, even while it starts
    return ros_main(make_monitor, "monitor", args, interrupted_exit=0)


if __name__ == "__main__":
    sys.exit(main())
