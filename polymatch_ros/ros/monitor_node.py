"""The monitor: hears every agent's pose and publishes the ensemble's diameters.

    ros2 run polymatch_ros monitor --ros-args -p scene:=config/congruent_triangles.yaml
    ros2 topic echo /polymatch/diameter

Publishes (ensemble namespace ``/<ns>``):
  /<ns>/diameter            std_msgs/Float64  the paper's matching diameter max_{i,j,a} |x^i_a - x^j_a|
                                              (max over groups; similar groups at their mean scale)
  /<ns>/diameter/centroid   std_msgs/Float64  max_{i,j} |xbar_i - xbar_j| (max over groups)
  /<ns>/diameter/rotation   std_msgs/Float64  max_{i,j} |O_i - O_j|_F (max over groups)
  /diagnostics              diagnostic_msgs/DiagnosticArray: per-group diameters, energy,
                            orthogonality defect, agents heard, dropped messages
  /<ns>/markers             visualization_msgs/MarkerArray: each polytope's edges (LINE_LIST),
                            one colour per group, lifetime = peer_timeout so silent agents fade
In lockstep it reports each step once every agent's pose for that simulated time
has arrived; in realtime at ``rate`` Hz from the latest poses.  The headline
topics are RELIABLE + TRANSIENT_LOCAL (depth 1): a late `ros2 topic echo` still
gets the last value.
"""

import sys
import time
from dataclasses import asdict, replace

import numpy as np

from . import wire
from .agent_node import declare
from ..core.errors import ParameterError, PolymatchError
from ..core.metrics import ensemble_metrics
from ..core.model import GroupState, State
from .exchange import DropCounter
from .ros_env import teardown_watchdog

PARAMETERS = (
    ("scene", "", "scene file (YAML); required", None),
    ("ensemble", "polymatch", "ensemble namespace", None),
    ("mode", "lockstep", "lockstep: report each simulated time once all agents reached it; "
                         "realtime: report at 'rate' Hz from the latest poses", None),
    ("rate", 10.0, "realtime: reports per second", (0.01, 10000.0)),
    ("peer_timeout", 1.0, "realtime: ignore agents silent this long (s); also the markers' lifetime",
     (0.001, 1e6)),
    ("frame_id", "world", "expected frame_id of poses and frame of the markers", None),
    ("markers", True, "publish visualization_msgs/MarkerArray", None),
    ("t_end", 0.0, "end time (0 = the scene's); used only to report progress", (0.0, 1e12)),
)

GROUP_COLOURS = [(0.12, 0.47, 0.71), (0.84, 0.15, 0.16), (0.17, 0.63, 0.17), (0.58, 0.40, 0.74),
                 (1.0, 0.50, 0.05), (0.09, 0.75, 0.81)]


class MonitorNode:
    def __init__(self):
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.node import Node
        from ..core.scene import resolve_scene_path
        from ..core.scene import load_scene
        self.node = Node("polymatch_monitor")
        self.log = self.node.get_logger()
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)
        p = declare(self.node, PARAMETERS)
        if not p["scene"]:
            raise ParameterError("parameter 'scene' is required (a scene file)")
        if p["mode"] not in ("lockstep", "realtime"):
            raise ParameterError(f"parameter 'mode': expected lockstep or realtime, got {p['mode']!r}")
        self.params = p
        self.scene = load_scene(resolve_scene_path(p["scene"]), {"time.t_end": p["t_end"] or None})
        self.model = self.scene.model
        self.grp = self.model.rotations
        self.n = self.model.n_agents
        self.drops = DropCounter(self.log)
        self.latest = {}                 # agent -> (t, x, rot, heard)
        self.velocity = {}               # agent -> (t, v, w)
        self.pending = {}                # time key -> {agent: (x, rot)}   (lockstep)
        self.pending_v = {}
        self.reported = -1
        self.last_metrics = None
        self.reports = 0
        self._subscribe()
        self._advertise()
        if p["mode"] == "realtime":
            self.node.create_timer(1.0 / p["rate"], self._report_latest)

    # -- wiring -----------------------------------------------------------------------------
    def _subscribe(self):
        qos = wire.qos_profiles()["pose" if self.params["mode"] == "lockstep" else "latest"]
        ens = self.params["ensemble"]
        if self.model.dim <= 3:
            from geometry_msgs.msg import PoseStamped, TwistStamped
            pose_t, twist_t = PoseStamped, TwistStamped
        else:
            from std_msgs.msg import Float64MultiArray
            pose_t = twist_t = Float64MultiArray
        for a in range(self.n):
            self.node.create_subscription(pose_t, wire.agent_topic(ens, a, "pose"), self._pose_cb(a), qos)
            if self.model.order == 2:
                self.node.create_subscription(twist_t, wire.agent_topic(ens, a, "twist"), self._twist_cb(a), qos)

    def _advertise(self):
        from diagnostic_msgs.msg import DiagnosticArray
        from std_msgs.msg import Float64
        from visualization_msgs.msg import MarkerArray
        latched = wire.qos_profiles()["latched"]
        ens = self.params["ensemble"]
        self.pub = {name: self.node.create_publisher(Float64, wire.ensemble_topic(ens, topic), latched)
                    for name, topic in (("diameter", "diameter"), ("centroid", "diameter/centroid"),
                                        ("rotation", "diameter/rotation"))}
        self.diag_pub = self.node.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.marker_pub = (self.node.create_publisher(MarkerArray, wire.ensemble_topic(ens, "markers"), 10)
                           if self.params["markers"] else None)

    def _pose_cb(self, agent):
        def receive(msg):
            got, reason = wire.decode_pose_msg(msg, self.grp, self.model.dim, self.params["frame_id"])
            if got is None:
                self.drops(f"agent {agent}", reason)
                return
            key, x, rot = got.key, got.vec - self.scene.origin, got.rot
            self.latest[agent] = (key, x, rot, time.monotonic())
            if self.params["mode"] == "lockstep":
                if key <= self.reported:
                    self.drops(f"agent {agent}", "stale pose (a stamp from the past)")
                    return
                self.pending.setdefault(key, {})[agent] = (x, rot)
                self._report_complete()
        return receive

    def _twist_cb(self, agent):
        def receive(msg):
            got, reason = wire.decode_twist_msg(msg, self.grp, self.model.dim)
            if got is None:
                self.drops(f"agent {agent}", reason)
                return
            val = (got.vec, got.rot)
            self.velocity[agent] = (got.key,) + val
            if self.params["mode"] == "lockstep" and got.key > self.reported:
                self.pending_v.setdefault(got.key, {})[agent] = val
                self._report_complete()
        return receive

    # -- reporting --------------------------------------------------------------------------
    def _state_from(self, poses, velocities, agents):
        groups, model = [], self.model
        sub_groups = []
        for g in model.groups:
            rows = [a for a in g.indices if a in agents]
            idx = np.array([a - g.start for a in rows], dtype=int)
            if not rows:
                sub_groups.append(None)
                groups.append(None)
                continue
            x = np.array([poses[a][0] for a in rows])
            rot = self.grp.concat([poses[a][1] for a in rows])
            v = w = None
            if model.order == 2 and all(a in velocities for a in rows):
                v = np.array([velocities[a][0] for a in rows])
                w = self.grp.algebra_concat([velocities[a][1] for a in rows])
            groups.append(GroupState(x, rot, v, w))
            sub_groups.append(replace(g, size=len(rows), scales=None if g.scales is None else g.scales[idx]))
        keep = [i for i, gs in enumerate(groups) if gs is not None]
        sub_model = replace(model, groups=tuple(sub_groups[i] for i in keep))
        return sub_model, State(0.0, tuple(groups[i] for i in keep)), keep

    def _report_complete(self):
        """Lockstep: publish every simulated time that all agents (and velocities) have reached."""
        need_v = self.model.order == 2
        for key in sorted(self.pending):
            poses = self.pending[key]
            if len(poses) < self.n or (need_v and len(self.pending_v.get(key, {})) < self.n):
                break
            vel = self.pending_v.pop(key, {})
            del self.pending[key]
            self.reported = key
            self._publish(key * 1e-9, poses, vel, range(self.n))
        for key in [k for k in self.pending if k <= self.reported]:
            del self.pending[key]

    def _report_latest(self):
        now = time.monotonic()
        alive = [a for a, v in self.latest.items() if now - v[3] <= self.params["peer_timeout"]]
        if not alive:
            return
        poses = {a: (self.latest[a][1], self.latest[a][2]) for a in alive}
        vel = {a: self.velocity[a][1:] for a in alive if a in self.velocity}
        t = max(self.latest[a][0] for a in alive) * 1e-9
        self._publish(t, poses, vel, alive)

    def _publish(self, t, poses, velocities, agents):
        from std_msgs.msg import Float64
        model, state, keep = self._state_from(poses, velocities, set(agents))
        met = ensemble_metrics(model, state)
        self.last_metrics = (t, met, len(poses))
        self.reports += 1
        for name, value in (("diameter", met.diameter),
                            ("centroid", max(g.centroid_diameter for g in met.groups)),
                            ("rotation", max(g.rotation_diameter for g in met.groups))):
            self.pub[name].publish(Float64(data=float(value)))
        self._diagnostics(t, met, keep, len(poses))
        if self.marker_pub is not None:
            self._markers(poses)

    def _diagnostics(self, t, met, keep, heard):
        from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
        arr = DiagnosticArray()
        arr.header.stamp = self.node.get_clock().now().to_msg()
        ens = self.params["ensemble"]
        top = DiagnosticStatus(name=f"polymatch/{ens}/monitor", hardware_id="monitor")
        ok = met.diameter < self.scene.tolerance
        top.level = DiagnosticStatus.OK if ok else DiagnosticStatus.WARN
        top.message = (f"t = {t:.6g}: matching diameter {met.diameter:.3e} "
                       f"({'below' if ok else 'above'} tolerance {self.scene.tolerance:g}); "
                       f"{heard}/{self.n} agents heard; {self.drops.summary()}")
        values = {"t": t, "diameter": met.diameter, "agents_heard": heard, "agents": self.n,
                  "dropped": self.drops.total}
        if met.group_separation is not None:
            values["group_separation"] = met.group_separation
        top.values = [KeyValue(key=k, value=repr(float(v)) if isinstance(v, float) else str(v))
                      for k, v in values.items()]
        statuses = [top]
        for gi, gm in zip(keep, met.groups):
            g = self.model.groups[gi]
            st = DiagnosticStatus(name=f"polymatch/{ens}/group/{g.name}", hardware_id=g.name,
                                  level=DiagnosticStatus.OK, message=f"matching diameter {gm.matching_diameter:.3e}")
            st.values = [KeyValue(key=k, value=repr(float(v))) for k, v in asdict(gm).items()]
            statuses.append(st)
        arr.status = statuses
        self.diag_pub.publish(arr)

    def _markers(self, poses):
        from builtin_interfaces.msg import Duration
        from geometry_msgs.msg import Point
        from visualization_msgs.msg import Marker, MarkerArray
        arr = MarkerArray()
        life = self.params["peer_timeout"]
        stamp = self.node.get_clock().now().to_msg()
        for gi, g in enumerate(self.model.groups):
            r, gcol, b = GROUP_COLOURS[gi % len(GROUP_COLOURS)]
            for a in g.indices:
                if a not in poses:
                    continue
                x, rot = poses[a]
                mat = self.grp.to_matrices(rot)[0]
                s = 1.0 if g.scales is None else g.scales[a - g.start]
                verts = x + self.scene.origin + s * g.reference @ mat.T
                m = Marker(type=Marker.LINE_LIST, action=Marker.ADD, ns=g.name, id=a)
                m.header.frame_id = self.params["frame_id"]
                m.header.stamp = stamp
                m.scale.x = 0.03
                m.color.r, m.color.g, m.color.b, m.color.a = r, gcol, b, 1.0
                m.pose.orientation.w = 1.0
                m.lifetime = Duration(sec=int(life), nanosec=int((life % 1) * 1e9))
                for ea, eb in g.edges:
                    for v in (verts[ea], verts[eb]):
                        pt = np.zeros(3)
                        pt[:min(3, len(v))] = v[:3]
                        m.points.append(Point(x=float(pt[0]), y=float(pt[1]), z=float(pt[2])))
                arr.markers.append(m)
        self.marker_pub.publish(arr)

    def spin(self):
        while True:
            self.executor.spin_once(timeout_sec=0.5)

    def destroy(self):
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()


def main(args=None):
    import rclpy
    from rclpy.executors import ExternalShutdownException
    argv = sys.argv if args is None else args
    rclpy.init(args=argv)
    mon = None
    code = 0
    try:
        mon = MonitorNode()
        mon.spin()
    except PolymatchError as exc:
        print(f"monitor: error: {exc}", file=sys.stderr, flush=True)
        code = exc.exit_code
    except (KeyboardInterrupt, ExternalShutdownException):
        code = 0
    finally:
        if mon is not None:
            if mon.last_metrics is not None:
                t, met, heard = mon.last_metrics
                print(f"monitor: last report t = {t:.6g}, matching diameter {met.diameter:.3e}, "
                      f"{heard} agents heard, {mon.reports} reports; {mon.drops.summary()}", flush=True)
        with teardown_watchdog():
            if mon is not None:
                mon.destroy()
            if rclpy.ok():
                rclpy.shutdown()
    return code


if __name__ == "__main__":
    sys.exit(main())
