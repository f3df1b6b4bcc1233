"""The polytope agent: an rclpy node that steps its own polytope(s) with the core's stepper.

    ros2 run polymatch_ros agent --ros-args -p scene:=config/congruent_triangles.yaml -p agent:=3
    agent --ros-args -p scene:=... -p agent:=3 -p mode:=realtime        (installed console script)

It publishes its pose (and velocity, second order) and hears its peers:
``lockstep`` exchanges every integrator stage with the group (and, for F-2,
the other groups' centroids) so the trajectory equals ``polymatch simulate``
to round-off; ``realtime`` steps on a wall-clock timer with the latest pose of
each peer, dropping peers that fall silent and re-admitting them when they speak.
"""

import sys
import time


from . import wire
from ..core.errors import ParameterError, PolymatchError
from ..core.model import GroupState, State, System
from ..core.simulate import drive, plan, prepare, step_grid
from .exchange import DropCounter, Layout, LockstepExchange, PeerTable, RoundTimeout
from .ros_env import teardown_watchdog

# name, default, description, (min, max) or None
PARAMETERS = (
    ("scene", "", "scene file (YAML); required", None),
    ("agent", 0, "index of the agent this process hosts (0-based over all groups)", (0, 1_000_000)),
    ("agents", None, "indices of the agents this process hosts (overrides 'agent')", None),
    ("agents_per_process", 1, "K of the runner's partition: process p hosts agents [pK, (p+1)K)", (1, 1_000_000)),
    ("ensemble", "polymatch", "ensemble namespace: topics /<ensemble>/agent_<i>/...", None),
    ("mode", "lockstep", "lockstep | realtime", None),
    ("integrator", "", "integrator name ('' = the scene's, see `polymatch integrators`)", None),
    ("dt", 0.0, "lockstep step size (0 = the scene's)", (0.0, 1e6)),
    ("t_end", 0.0, "end time (0 = the scene's)", (0.0, 1e12)),
    ("rate", 50.0, "realtime: steps per wall-clock second", (0.01, 100000.0)),
    ("time_scale", 1.0, "realtime: simulated seconds per wall-clock second", (1e-6, 1e6)),
    ("start_time", 0.0, "realtime: wall-clock time (s since the epoch) of t = 0; 0 = when this agent starts; "
                        "-1 = wait for 'start <epoch>' on /<ensemble>/control", (-1.0, 1e12)),
    ("peer_timeout", 1.0, "realtime: seconds of silence after which a peer is dropped from the sums",
     (0.001, 1e6)),
    ("delay", 0.0, "realtime: injected transport delay (s) before a peer's pose is used (experiments)",
     (0.0, 1e6)),
    ("round_timeout", 10.0, "lockstep: seconds to wait for a round before giving up (the first round: "
                            "plus discovery_timeout)", (0.001, 1e6)),
    ("discovery_timeout", 30.0, "seconds to wait until every peer is matched", (0.0, 1e6)),
    ("pose_subscribers", 0, "do not start before this many subscribers listen to the poses", (0, 100000)),
    ("frame_id", "world", "frame_id of published poses", None),
    ("run_id", 0, "run identifier shared by the ensemble; stage messages with another are dropped",
     (0, 2 ** 31 - 1)),
)


def declare(node, spec):
    """Declare parameters with descriptors and ranges; return their values (ParameterError if bad)."""
    from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
    from rclpy.exceptions import (InvalidParameterTypeException, InvalidParameterValueException,
                                  ParameterUninitializedException)
    from rclpy.parameter import Parameter
    values = {}
    for name, default, text, bounds in spec:
        desc = ParameterDescriptor(description=text, read_only=True)
        if isinstance(default, float):
            desc.dynamic_typing = True     # accept `t_end:=2` as well as `t_end:=2.0`
            if bounds is not None:
                desc.floating_point_range = [FloatingPointRange(from_value=float(bounds[0]),
                                                                to_value=float(bounds[1]), step=0.0)]
        elif bounds is not None and isinstance(default, int):
            desc.integer_range = [IntegerRange(from_value=int(bounds[0]), to_value=int(bounds[1]), step=1)]
        initial = Parameter.Type.INTEGER_ARRAY if default is None else default
        try:
            node.declare_parameter(name, initial, desc)
            value = node.get_parameter(name).value
            if isinstance(default, float):
                if isinstance(value, bool) or not isinstance(value, (int, float)):
                    raise ParameterError(f"parameter {name!r}: expected a number, got {value!r}")
                value = float(value)
                if bounds is not None and not bounds[0] <= value <= bounds[1]:
                    raise ParameterError(f"parameter {name!r}: {value:g} is out of range "
                                         f"[{bounds[0]:g}, {bounds[1]:g}]")
            values[name] = value
        except ParameterUninitializedException:
            values[name] = None
        except (InvalidParameterTypeException, InvalidParameterValueException) as exc:
            raise ParameterError(f"parameter {name!r}: {str(exc).splitlines()[0]}") from None
    return values


def local_state(scene, layout):
    grp = scene.model.rotations
    groups = []
    for gs, rows in zip(scene.initial.groups, layout.rows):
        groups.append(GroupState(gs.x[rows].copy(), grp.take(gs.rot, rows),
                                 None if gs.v is None else gs.v[rows].copy(),
                                 None if gs.w is None else grp.algebra_take(gs.w, rows)))
    return State(0.0, tuple(groups))


class AgentNode:
    """Wraps the rclpy node; ``run()`` returns the process exit code."""

    def __init__(self, args=None):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.node import Node
        self.node = Node(_node_name(args), automatically_declare_parameters_from_overrides=False)
        self.created = time.monotonic()
        self.matched_after = None
        self.log = self.node.get_logger()
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)
        self._rclpy = rclpy
        p = declare(self.node, PARAMETERS)
        self.params = p
        self._configure(p)

    # -- configuration --------------------------------------------------------------------------
    def _configure(self, p):
        from ..core.scene import resolve_scene_path
        from ..core.scene import load_scene
        if not p["scene"]:
            raise ParameterError("parameter 'scene' is required (a scene file)")
        if p["mode"] not in ("lockstep", "realtime"):
            raise ParameterError(f"parameter 'mode': expected lockstep or realtime, got {p['mode']!r}")
        scene = load_scene(resolve_scene_path(p["scene"]), {"time.t_end": p["t_end"] or None})
        local = list(p["agents"]) if p["agents"] else [p["agent"]]
        bad = [a for a in local if not 0 <= a < scene.model.n_agents]
        if bad:
            raise ParameterError(f"parameter 'agents': agent {bad[0]} is not in the scene "
                                 f"(0..{scene.model.n_agents - 1})")
        self.mode = p["mode"]
        if self.mode == "realtime":
            dt = p["time_scale"] / p["rate"]
            self.plan = plan(scene, p["integrator"] or None, dt, distributed=True)
        else:
            self.plan = plan(scene, p["integrator"] or None, p["dt"] or None, distributed=True)
        scene = prepare(scene, self.plan)
        self.scene = scene
        self.model = scene.model
        self.grp = self.model.rotations
        self.layout = Layout(self.model, local, p["agents_per_process"])
        self.system = System(self.model, self.layout.rows)
        self.state = local_state(scene, self.layout)
        self.drops = DropCounter(self.log)
        self.stop_requested = False
        self.start_epoch = None
        self.rounds = 0
        self.steps = 0
        self.round_time = 0.0
        self.ensemble = p["ensemble"]
        self._make_publishers()
        if self.mode == "lockstep":
            rot_tol = 1e-9 if self.plan.method.info.family != "projection" else 0.5
            self.exchange = LockstepExchange(self.node.get_name() + "_stages", self.layout, self.ensemble,
                                             p["run_id"], rot_tol, self.drops)
        else:
            self.peers = PeerTable(self.node, self.layout, self.ensemble, p["frame_id"], p["peer_timeout"],
                                   self.drops, scene.origin, p["delay"])

    def _make_publishers(self):
        from diagnostic_msgs.msg import DiagnosticArray
        from std_msgs.msg import String
        qos = wire.qos_profiles()
        dim = self.model.dim
        if dim <= 3:
            from geometry_msgs.msg import PoseStamped, TwistStamped
            self._pose_t, self._twist_t = PoseStamped, TwistStamped
        else:
            from std_msgs.msg import Float64MultiArray, MultiArrayDimension
            self._pose_t = self._twist_t = Float64MultiArray
            self._dim_t = MultiArrayDimension
        self.pose_pubs = {a: self.node.create_publisher(self._pose_t, wire.agent_topic(self.ensemble, a, "pose"),
                                                        qos["pose"]) for a in self.layout.local}
        self.twist_pubs = {}
        if self.model.order == 2:
            self.twist_pubs = {a: self.node.create_publisher(self._twist_t,
                                                             wire.agent_topic(self.ensemble, a, "twist"),
                                                             qos["pose"]) for a in self.layout.local}
        self.diag_pub = self.node.create_publisher(DiagnosticArray, "/diagnostics", 10)
        # the final state, latched, for whoever supervises the run (the runner's summary)
        self.final_pubs = {a: self.node.create_publisher(self._pose_t, wire.agent_topic(self.ensemble, a, "final_pose"),
                                                         qos["latched"]) for a in self.layout.local}
        self.final_twist_pubs = {}
        if self.model.order == 2:
            self.final_twist_pubs = {a: self.node.create_publisher(
                self._twist_t, wire.agent_topic(self.ensemble, a, "final_twist"), qos["latched"])
                for a in self.layout.local}
        self.node.create_subscription(String, wire.ensemble_topic(self.ensemble, "control"), self._control,
                                      qos["control"])
        self._last_diag = 0.0

    def _control(self, msg):
        words = msg.data.strip().lower().split()
        if words == ["stop"] and not self.stop_requested:
            self.log.info("stop requested")
            self.stop_requested = True
        elif len(words) == 2 and words[0] == "start" and self.start_epoch is None:
            try:
                self.start_epoch = float(words[1])
            except ValueError:
                self.drops("control", f"bad command {msg.data!r}")

    # -- publishing ------------------------------------------------------------------------------
    def publish_state(self, final=False):
        """Publish every local agent's pose (and velocity); ``final`` also on the latched final topics.

        Per-step poses nobody subscribes to are not even built (the lockstep hot loop).
        """
        if not final and not any(p.get_subscription_count() for p in self.pose_pubs.values()):
            self._maybe_diagnostics()
            return
        st = self.state
        sec, nsec = wire.stamp_of(st.t)
        for gi in self.layout.local_groups:
            gs = st.groups[gi]
            g = self.model.groups[gi]
            for r, row in enumerate(self.layout.rows[gi]):
                a = g.start + row
                x = gs.x[r] + self.scene.origin
                one = self.grp.take(gs.rot, [r])
                if self.model.dim <= 3:
                    msg = self._pose_t()
                    msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nsec
                    msg.header.frame_id = self.params["frame_id"]
                    pos, quat = wire.pose_fields(self.grp, x, one)
                    msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = map(float, pos)
                    o = msg.pose.orientation
                    o.x, o.y, o.z, o.w = map(float, quat)
                else:
                    msg = wire.array_pose(self._dim_t, self._pose_t, st.t, x, self.grp.to_matrices(one)[0])
                self.pose_pubs[a].publish(msg)
                if final:
                    self.final_pubs[a].publish(msg)
                if self.model.order == 2:
                    w_one = self.grp.algebra_take(gs.w, [r])
                    if self.model.dim <= 3:
                        tw = self._twist_t()
                        tw.header.stamp.sec, tw.header.stamp.nanosec = sec, nsec
                        tw.header.frame_id = self.params["frame_id"]
                        lin, ang = wire.twist_fields(self.grp, gs.v[r], w_one)
                        tw.twist.linear.x, tw.twist.linear.y, tw.twist.linear.z = map(float, lin)
                        tw.twist.angular.x, tw.twist.angular.y, tw.twist.angular.z = map(float, ang)
                    else:
                        tw = wire.array_pose(self._dim_t, self._twist_t, st.t, gs.v[r],
                                             self.grp.algebra_to_skew(w_one)[0],
                                             labels=("t", "velocity", "angular_row_major"))
                    self.twist_pubs[a].publish(tw)
                    if final:
                        self.final_twist_pubs[a].publish(tw)
        self._maybe_diagnostics()

    def time_split(self):
        """Milliseconds per round spent publishing stages, waiting for peers, and everything else."""
        ex = getattr(self, "exchange", None)
        if ex is None or self.rounds == 0:
            return {}
        pub, wait = ex.publish_time / self.rounds * 1e3, ex.wait_time / self.rounds * 1e3
        rest = max(0.0, self.round_time / self.rounds * 1e3 - pub - wait)
        return {"publish_ms_per_round": pub, "wait_ms_per_round": wait, "other_ms_per_round": rest}

    def flush_poses(self, timeout=3.0):
        """Wait until the last poses reached every subscriber (the monitor, the runner)."""
        from rclpy.duration import Duration
        pubs = [self.pose_pubs, self.twist_pubs, self.final_pubs, self.final_twist_pubs]
        for pub in [p for group in pubs for p in group.values()]:
            pub.wait_for_all_acked(Duration(seconds=timeout))

    def _maybe_diagnostics(self, force=False):
        now = time.monotonic()
        if not force and now - self._last_diag < 1.0:
            return
        self._last_diag = now
        from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
        arr = DiagnosticArray()
        arr.header.stamp = self.node.get_clock().now().to_msg()
        status = DiagnosticStatus()
        status.name = f"polymatch/{self.ensemble}/{self.node.get_name()}"
        status.hardware_id = "agents " + ",".join(map(str, self.layout.local))
        status.level = DiagnosticStatus.OK if self.drops.total == 0 else DiagnosticStatus.WARN
        status.message = f"{self.mode}: t = {self.state.t:.4g}; {self.drops.summary()}"
        rps = self.rounds / self.round_time if self.round_time > 0 else 0.0
        vals = {"t": self.state.t, "steps": self.steps, "rounds": self.rounds, "rounds_per_second": rps,
                "dropped": self.drops.total}
        vals.update(self.time_split())
        vals.update({f"dropped: {k}": v for k, v in self.drops.counts.items()})
        status.values = [KeyValue(key=k, value=f"{v:.6g}" if isinstance(v, float) else str(v))
                         for k, v in vals.items()]
        arr.status = [status]
        self.diag_pub.publish(arr)

    # -- running ---------------------------------------------------------------------------------
    def spin_once(self, timeout):
        self.executor.spin_once(timeout_sec=timeout)

    def wait_for_discovery(self, need_peers):
        deadline = time.monotonic() + self.params["discovery_timeout"]
        want = self.params["pose_subscribers"]
        while True:
            peers_ok = (not need_peers) or self.exchange.matched()
            subs_ok = all(p.get_subscription_count() >= want for p in self.pose_pubs.values())
            if peers_ok and subs_ok:
                self.matched_after = time.monotonic() - self.created
                return
            if need_peers:
                self.exchange.spin_once(0.0)
            if time.monotonic() > deadline:
                missing = self.exchange.missing_peers() if need_peers else []
                what = f"agent(s) {', '.join(map(str, missing))}" if missing else "all subscribers"
                raise PolymatchError(f"discovery timed out after {self.params['discovery_timeout']:g} s "
                                     f"waiting for {what}")
            self.spin_once(0.05)

    def run_lockstep(self):
        self.wait_for_discovery(need_peers=True)
        self.publish_state()
        grid = step_grid(self.scene.t_end, self.plan.dt)
        method = self.plan.method
        prev = 0.0
        timeout = self.params["round_timeout"]
        # matching is not simultaneous: a peer that matched us may still be matching others and
        # start later, so the first round also allows the peers' discovery time
        first_wait = timeout + self.params["discovery_timeout"]
        start = last_spin = time.monotonic()
        for k, t_next in enumerate(grid):
            stop = False

            def answer(request, stage):
                nonlocal stop
                wait = first_wait if k == 0 and stage == 0 else timeout
                ensemble, stop_seen = self.exchange.round(k, stage, request, self.stop_requested, wait)
                stop = stop or (request.boundary and stop_seen)
                self.rounds += 1
                return ensemble

            self.state = drive(method, self.system, self.state, t_next - prev, answer)
            self.state.t = t_next
            prev = t_next
            self.steps += 1
            now = time.monotonic()
            self.round_time = now - start
            self.publish_state()
            # the node's own entities (control topic, parameter services) cost a full wait-set
            # rebuild per spin: serve them a few times a second, not every step
            if now - last_spin > 0.1:
                self.spin_once(0.0)
                last_spin = now
            if stop:
                break
        self.publish_state(final=True)
        self.exchange.flush()
        self.flush_poses()
        split = ", ".join(f"{k.split('_ms')[0]} {v:.2f}" for k, v in self.time_split().items())
        return f"finished at t = {self.state.t:.6g} after {self.steps} steps ({self.rounds} rounds, " \
               f"{self.rounds / max(self.round_time, 1e-9):.1f} rounds/s; ms per round: {split})"

    def run_realtime(self):
        p = self.params
        self.wait_for_discovery(need_peers=False)
        self.publish_state()
        if p["start_time"] < 0:                                      # wait for the runner's 'start'
            last = 0.0
            while self.start_epoch is None and not self.stop_requested:
                self.spin_once(0.05)
                if time.monotonic() - last > 0.5:                    # keep announcing the initial pose
                    self.publish_state()
                    self._maybe_diagnostics(force=True)              # the runner counts agents that are up
                    last = time.monotonic()
            start = self.start_epoch if self.start_epoch is not None else time.time()
        else:
            start = p["start_time"] or time.time()
        while time.time() < start and not self.stop_requested:      # the ensemble starts together
            self.spin_once(min(0.05, max(0.0, start - time.time())))
        h = self.plan.dt
        method = self.plan.method
        period = 1.0 / p["rate"]
        next_tick = self._join_clock(start, period, h)
        t0 = time.monotonic()
        late = 0
        while self.state.t < self.scene.t_end - 1e-12 and not self.stop_requested:
            next_tick += period
            while True:
                left = next_tick - time.monotonic()
                if left <= 0 or self.stop_requested:
                    break
                self.spin_once(min(left, 0.05))
            if time.monotonic() - next_tick > period:               # behind schedule: the CPU is short
                late += 1
            for _ in range(len(self.peers.subs) + 2):                 # drain what is ready
                self.spin_once(0.0)
            alive = self.peers.active()
            self.state.coupling = None
            t = self.state.t
            self.state = drive(method, self.system, self.state, h,
                               lambda request, stage: self.peers.ensemble(request, alive))
            self.state.t = t + h
            self.steps += 1
            self.rounds += 1
            self.round_time = time.monotonic() - t0
            self.publish_state()
        self.publish_state(final=True)
        self.flush_poses()
        return (f"finished at t = {self.state.t:.6g} after {self.steps} realtime steps, "
                f"{late} started more than one period late")

    def _join_clock(self, start, period, h):
        """Set the initial simulated time of a realtime run; return the monotonic time of tick 0.

        Tick k is due at ``start + k * period`` on every agent, and an agent a little late (a
        loaded CPU) catches up tick by tick.  An agent (re)joining a running ensemble - later
        than the peer timeout - starts from its initial state on the ensemble's clock instead of
        replaying the past: the newest simulated time its peers publish, so that it agrees with
        an ensemble that runs behind the wall-clock schedule (a CPU short of the rate), or the
        wall-clock schedule when it hears no peer within the peer timeout.
        """
        behind = max(0.0, time.time() - start)
        if behind <= self.params["peer_timeout"]:
            self.state.t = 0.0
            return time.monotonic() - behind
        heard_by = time.monotonic() + self.params["peer_timeout"]
        while self.peers.newest_time() is None and time.monotonic() < heard_by and not self.stop_requested:
            self.spin_once(0.05)
        newest = self.peers.newest_time()
        skipped = int(round(newest / h)) if newest is not None else int(behind / period)
        self.state.t = skipped * h
        return time.monotonic() if newest is not None else time.monotonic() - (behind - skipped * period)

    def run(self):
        text = self.run_lockstep() if self.mode == "lockstep" else self.run_realtime()
        self._maybe_diagnostics(force=True)
        names = ",".join(map(str, self.layout.local))
        if self.matched_after is not None:
            text += f"; peers matched after {self.matched_after:.2f} s"
        print(f"agent {names}: {text}; {self.drops.summary()}", flush=True)
        return 0

    def destroy(self):
        if getattr(self, "exchange", None) is not None:
            self.exchange.destroy()
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()


def _node_name(args):
    """agent_<i> from ``-p agent:=i`` (or agents_<first>_<last>) so the graph shows who is who."""
    args = sys.argv if args is None else args
    for a in args:
        if a.startswith("agent:="):
            return f"agent_{a.split(':=', 1)[1].strip()}"
        if a.startswith("agents:="):
            ids = [s for s in a.split(":=", 1)[1].strip("[] ").split(",") if s.strip()]
            if ids:
                return f"agents_{ids[0].strip()}_{ids[-1].strip()}"
    return "polymatch_agent"


def main(args=None):
    import rclpy
    from rclpy.executors import ExternalShutdownException
    argv = sys.argv if args is None else args
    rclpy.init(args=argv)
    agent = None
    code = 0
    try:
        agent = AgentNode(argv)
        code = agent.run()
    except PolymatchError as exc:
        print(f"agent: error: {exc}", file=sys.stderr, flush=True)
        code = exc.exit_code
    except RoundTimeout as exc:
        print(f"agent: error: {exc}", file=sys.stderr, flush=True)
        code = 1
    except (KeyboardInterrupt, ExternalShutdownException):
        code = 130
    finally:
        with teardown_watchdog():
            if agent is not None:
                agent.destroy()
            if rclpy.ok():
                rclpy.shutdown()
    return code


if __name__ == "__main__":
    sys.exit(main())
