"""What an agent process hears from its peers: lockstep stage rounds and realtime pose tables.

Both produce the *ensemble* the core's steppers ask for: per group, full arrays
(x, rot, v) of the agents that take part, in agent-index order, with the
process's own rows at their current stage values.  The core then computes the
mean field from them exactly as the centralised simulator does.
"""

import time
from collections import Counter, defaultdict
from types import SimpleNamespace

import numpy as np

from ..core.errors import PolymatchError
from . import wire


class Layout:
    """Which agents a process hosts and which peers each of them needs.

    ``local`` are global agent indices.  ``agents_per_process`` K gives the
    runner's partition (process p hosts [pK, (p+1)K)); it is used only to count
    how many remote processes subscribe to each local stage topic.
    """

    def __init__(self, model, local, agents_per_process=1):
        self.model = model
        self.local = sorted(set(int(a) for a in local))
        self.k = max(1, int(agents_per_process))
        self.owner = {a: model.group_of(a) for a in range(model.n_agents)}
        self.rows = []
        for gi, g in enumerate(model.groups):
            self.rows.append(np.array([a - g.start for a in self.local if self.owner[a][0] == gi], dtype=int))
        self.local_groups = [gi for gi, r in enumerate(self.rows) if len(r)]
        needed = set()
        for gi in self.local_groups:
            needed.update(self.model.groups[gi].indices)
        if model.inter_group:
            needed.update(range(model.n_agents))
        self.peers = sorted(needed - set(self.local))
        self.groups_needed = sorted({self.owner[a][0] for a in needed | set(self.local)})

    def process_of(self, agent):
        return agent // self.k

    def expected_subscribers(self, agent):
        """Remote processes that need ``agent``'s stage messages."""
        gi = self.owner[agent][0]
        me = self.process_of(agent)
        procs = set()
        for b in range(self.model.n_agents):
            if self.process_of(b) == me:
                continue
            if self.owner[b][0] == gi or self.model.inter_group:
                procs.add(self.process_of(b))
        return len(procs)


class DropCounter:
    """Counts dropped messages by reason and warns at most once a second per reason."""

    def __init__(self, logger):
        self.logger = logger
        self.counts = Counter()

    def __call__(self, source, reason):
        self.counts[reason] += 1
        self.logger.warning(f"dropped a message from {source}: {reason} "
                            f"({self.counts[reason]} so far)", throttle_duration_sec=1.0)

    @property
    def total(self):
        return sum(self.counts.values())

    def summary(self):
        if not self.counts:
            return "no messages dropped"
        parts = ", ".join(f"{r}: {n}" for r, n in sorted(self.counts.items()))
        return f"dropped {self.total} messages ({parts})"


class RoundTimeout(PolymatchError):
    pass


def _blank_group(grp, n, dim, with_v):
    return SimpleNamespace(x=np.zeros((n, dim)), rot=grp.identity(n),
                           v=np.zeros((n, dim)) if with_v else None, index=None)


def lean_node(name):
    """A node with nothing but what the exchange adds: no parameter services, no rosout.

    rclpy's executor rebuilds its wait set from every entity of its nodes at each
    spin, so the lockstep stages get a node (and an executor) of their own.
    """
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    node = Node(name, start_parameter_services=False, enable_rosout=False)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    return node, executor


def quiet_events():
    """(publisher, subscription) event callbacks without rclpy's default QoS-event waitables."""
    from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
    return (PublisherEventCallbacks(use_default_callbacks=False),
            SubscriptionEventCallbacks(use_default_callbacks=False))


class LockstepExchange:
    """Stage rounds: publish the local stage rows, wait for every peer's message of the same round.

    Runs on its own lean node and executor (``lean_node``); ``spin_once`` waits on
    nothing but the peers' stage topics.
    """

    def __init__(self, name, layout, ensemble, run_id, rot_tol, drops):
        from std_msgs.msg import Float64MultiArray
        self.node, self.executor = lean_node(name)
        self.layout, self.run_id, self.drops = layout, int(run_id), drops
        self.model = layout.model
        self.grp = self.model.rotations
        self.rot_tol = rot_tol
        pub_events, sub_events = quiet_events()
        qos = wire.qos_profiles()["stage"]
        self.pubs = {a: self.node.create_publisher(Float64MultiArray, wire.agent_topic(ensemble, a, "stage"), qos,
                                                   event_callbacks=pub_events)
                     for a in layout.local}
        self._out = {a: Float64MultiArray() for a in layout.local}     # reused: rclpy copies on publish
        self.inbox = defaultdict(dict)            # agent -> {(step, stage): Stage}
        self.current = (0, 0)
        qos_in = wire.qos_profiles()["stage_in"]
        self.subs = [self.node.create_subscription(Float64MultiArray, wire.agent_topic(ensemble, a, "stage"),
                                                   self._callback(a), qos_in, event_callbacks=sub_events)
                     for a in layout.peers]
        self.publish_time = 0.0       # seconds spent publishing stages (for the diagnostics)
        self.wait_time = 0.0          # seconds spent waiting for (and taking) the peers' stages

    def _callback(self, agent):
        def receive(msg):
            stage, reason = wire.decode_stage(msg, self.grp, self.model.dim, self.run_id, agent, self.rot_tol)
            if stage is None:
                self.drops(f"agent {agent}", reason)
                return
            key = (stage.step, stage.stage)
            if key < self.current:
                self.drops(f"agent {agent}", "stale round (a stamp from the past)")
                return
            self.inbox[agent][key] = stage
        return receive

    def matched(self):
        """(all peers' publishers matched, all expected remote subscribers matched)."""
        subs_ok = all(s.get_publisher_count() >= 1 for s in self.subs)
        pubs_ok = all(p.get_subscription_count() >= self.layout.expected_subscribers(a)
                      for a, p in self.pubs.items())
        return subs_ok and pubs_ok

    def missing_peers(self):
        return [a for a, s in zip(self.layout.peers, self.subs) if s.get_publisher_count() < 1]

    def publish(self, step, stage, request, stop_flag):
        flags = wire.FLAG_STOP if stop_flag else 0
        st = request.stage
        for gi in self.layout.local_groups:
            gs = st.groups[gi]
            g = self.model.groups[gi]
            for r, row in enumerate(self.layout.rows[gi]):
                fields = {"rot": wire.rot_values(self.grp, self.grp.take(gs.rot, [r]))}
                if "x" in request.fields:
                    fields["x"] = gs.x[r].tolist()
                if "v" in request.fields and gs.v is not None:
                    fields["v"] = gs.v[r].tolist()
                a = g.start + row
                wire.encode_stage(self._out[a], self.run_id, a, step, stage, flags, st.t, fields)
                self.pubs[a].publish(self._out[a])

    def spin_once(self, timeout):
        self.executor.spin_once(timeout_sec=timeout)

    def round(self, step, stage, request, stop_flag, timeout):
        """Publish, wait, assemble: returns (ensemble, stop requested by anyone)."""
        key = (step, stage)
        self.current = key
        t0 = time.perf_counter()
        self.publish(step, stage, request, stop_flag)
        t1 = time.perf_counter()
        self.publish_time += t1 - t0
        deadline = time.monotonic() + timeout
        waiting = [a for a in self.layout.peers if key not in self.inbox[a]]
        while waiting:
            left = deadline - time.monotonic()
            if left <= 0:
                raise RoundTimeout(f"lockstep round (step {step}, stage {stage}) timed out after {timeout:g} s "
                                   f"waiting for agent(s) {', '.join(map(str, waiting))}")
            self.executor.spin_once(timeout_sec=min(left, 0.5))
            waiting = [a for a in waiting if key not in self.inbox[a]]
        self.wait_time += time.perf_counter() - t1
        stop = stop_flag or any(self.inbox[a][key].flags & wire.FLAG_STOP for a in self.layout.peers)
        return self._assemble(key, request), stop

    def _assemble(self, key, request):
        model, grp, dim = self.model, self.grp, self.model.dim
        st = request.stage
        out = []
        for gi, g in enumerate(model.groups):
            if gi not in self.layout.groups_needed:
                out.append(None)
                continue
            with_v = "v" in request.fields and model.order == 2
            e = _blank_group(grp, g.size, dim, with_v)
            if gi not in self.layout.local_groups:
                e.rot = None                     # other group: only its centroids are used (F-2)
            for a in g.indices:
                msg = self.inbox[a].get(key) if a in self.inbox else None
                if msg is None:
                    continue
                row = a - g.start
                if msg.x is not None:
                    e.x[row] = msg.x
                if with_v and msg.v is not None:
                    e.v[row] = msg.v
                if e.rot is not None:
                    grp.put(e.rot, [row], msg.rot)
            if gi in self.layout.local_groups:
                gs = st.groups[gi]
                rows = self.layout.rows[gi]
                e.x[rows] = gs.x
                if with_v:
                    e.v[rows] = gs.v
                grp.put(e.rot, rows, gs.rot)
            out.append(e)
        for a in self.layout.peers:
            self.inbox[a].pop(key, None)
        return tuple(out)

    def flush(self, timeout=5.0):
        """Wait until every stage message this process sent has been acknowledged."""
        from rclpy.duration import Duration
        for p in self.pubs.values():
            p.wait_for_all_acked(Duration(seconds=timeout))

    def destroy(self):
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()


class PeerTable:
    """Realtime: the latest pose (and velocity) heard from each peer, and who is still alive."""

    def __init__(self, node, layout, ensemble, frame_id, timeout, drops, origin, delay=0.0):
        self.node, self.layout, self.drops = node, layout, drops
        self.delay = float(delay)    # injected transport delay (s): a pose is used only this long after arrival
        self.pending = defaultdict(list)   # agent -> [(arrival, kind, values)] not yet delivered
        self.origin = np.asarray(origin, dtype=float)      # poses are absolute; the core works in offsets
        self.model = layout.model
        self.grp = self.model.rotations
        self.frame_id, self.timeout = frame_id, timeout
        self.latest = {}             # agent -> SimpleNamespace(t, x, rot, v, heard)
        self.silent = set()
        qos = wire.qos_profiles()["latest"]
        dim = self.model.dim
        self.subs = []
        want_v = self.model.order == 2 and self.model.centroids_exact
        if dim <= 3:
            from geometry_msgs.msg import PoseStamped, TwistStamped
            pose_t, twist_t = PoseStamped, TwistStamped
        else:
            from std_msgs.msg import Float64MultiArray
            pose_t = twist_t = Float64MultiArray
        for a in layout.peers:
            self.subs.append(node.create_subscription(pose_t, wire.agent_topic(ensemble, a, "pose"),
                                                      self._pose_cb(a), qos))
            if want_v and self.layout.owner[a][0] in layout.local_groups:
                self.subs.append(node.create_subscription(twist_t, wire.agent_topic(ensemble, a, "twist"),
                                                          self._twist_cb(a), qos))

    def _entry(self, agent):
        return self.latest.setdefault(agent, SimpleNamespace(t=-np.inf, x=None, rot=None, v=None, heard=0.0))

    def _pose_cb(self, agent):
        def receive(msg):
            got, reason = wire.decode_pose_msg(msg, self.grp, self.model.dim, self.frame_id)
            if got is None:
                self.drops(f"agent {agent}", reason)
                return
            self.pending[agent].append((time.monotonic(), "pose", (got.t, got.vec - self.origin, got.rot)))
        return receive

    def _deliver(self, now):
        """Move every pose and velocity that has waited ``delay`` into the table."""
        for agent, queue in self.pending.items():
            keep = []
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

    def _twist_cb(self, agent):
        def receive(msg):
            got, reason = wire.decode_twist_msg(msg, self.grp, self.model.dim)
            if got is None:
                self.drops(f"agent {agent}", reason)
                return
            self.pending[agent].append((time.monotonic(), "twist", got.vec))
        return receive

    def newest_time(self):
        """The newest simulated time heard from any peer (None if none heard): the ensemble's clock."""
        self._deliver(time.monotonic())
        times = [e.t for e in self.latest.values() if e.x is not None and np.isfinite(e.t)]
        return max(times) if times else None

    def active(self):
        """Peers heard within the timeout; logs once when one falls silent."""
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
                    self.node.get_logger().warning(f"agent {a} silent for {self.timeout:g} s: dropped from the sums")
                continue
            alive.append(a)
        return alive

    def ensemble(self, request, alive):
        """Frozen peers + the local stage rows, per needed group, with an ``index`` of rows present."""
        model, grp = self.model, self.grp
        st = request.stage
        out = []
        alive = set(alive)
        for gi, g in enumerate(model.groups):
            if gi not in self.layout.groups_needed:
                out.append(None)
                continue
            local_rows = list(self.layout.rows[gi])
            peers = [a - g.start for a in g.indices if a in alive]
            index = np.array(sorted(peers + local_rows), dtype=int)
            pos = {row: k for k, row in enumerate(index)}
            n = len(index)
            with_v = model.order == 2 and "v" in request.fields
            e = _blank_group(grp, n, model.dim, with_v)
            e.index = index
            for row in peers:
                p = self.latest[g.start + row]
                e.x[pos[row]] = p.x
                if with_v and p.v is not None:
                    e.v[pos[row]] = p.v
                grp.put(e.rot, [pos[row]], p.rot)
            if local_rows:
                gs = st.groups[gi]
                at = [pos[r] for r in local_rows]
                e.x[at] = gs.x
                if with_v:
                    e.v[at] = gs.v
                grp.put(e.rot, at, gs.rot)
            else:
                e.rot = None
            out.append(e)
        return tuple(out)
