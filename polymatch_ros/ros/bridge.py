"""Bridge: an agent that drives a robot.  Its state is the robot's measured pose; it commands the
robot's velocity with the first-order model (A-2).

    ros2 run polymatch_ros agent --ros-args -r __ns:=/polymatch -r __node:=agent_3 \\
        -p scene:=FILE -p agent:=3 -p mode:=bridge \\
        -r measured_pose:=/robot3/odom -p pose_type:=odometry -r cmd_vel:=/robot3/cmd_vel

Every tick (``rate`` Hz) the agent takes its own pose from ``measured_pose`` (PoseStamped or
nav_msgs/Odometry), relays it on ``agent_<i>/pose`` for its peers and the monitor (stamped
with the seconds since the ensemble's start), and publishes on ``cmd_vel`` (Twist or
TwistStamped) linear = xbar_i' and angular = the axial vector of W_i of (A-2) against the
peers' latest poses (``core.command``), saturated, in the world or the robot's body frame.

Safety: a measured pose older than ``pose_timeout``, a non-finite pose or command, and the
end of the run (t_end, 'stop', shutdown) publish one zero command; the agent then stays quiet
(no command, no relayed pose: its peers drop it after their peer timeout) until a fresh pose
arrives.  A pause (``control``) publishes one zero command at once and keeps relaying the
measured pose, so that the peers keep the robot; resume goes on at the next tick.  The reason
is in the diagnostics.
"""

import time
from types import SimpleNamespace

from ..core.command import ZERO, bridge_system, command_from_ensemble
from ..core.errors import ParameterError
from ..core.model import GroupState, State
from . import wire
from .agent_node import AgentBase
from .realtime import PeerTable, RealtimeAgent
from .runtime_params import RuntimeParams

#: relative names: remap them to a robot's topics (``-r cmd_vel:=/robot3/cmd_vel``)
MEASURED_POSE, CMD_VEL = "measured_pose", "cmd_vel"


def robot_qos():
    """Measured poses: the newest only, BEST_EFFORT (matches RELIABLE and BEST_EFFORT odometry
    publishers); commands: RELIABLE, depth 10 (what teleop tools and robot drivers use)."""
    from rclpy.qos import QoSProfile, qos_profile_sensor_data

    return qos_profile_sensor_data, QoSProfile(depth=10)


def pose_class(pose_type):
    if pose_type == "odometry":
        from nav_msgs.msg import Odometry

        return Odometry
    from geometry_msgs.msg import PoseStamped

    return PoseStamped


def twist_class(cmd_type):
    from geometry_msgs.msg import Twist, TwistStamped

    return TwistStamped if cmd_type == "twist_stamped" else Twist


def pose_of(msg):
    """The geometry_msgs/Pose inside a PoseStamped or an Odometry message."""
    return msg.pose.pose if hasattr(msg, "child_frame_id") else msg.pose


def fill_twist(msg, twist):
    """Write ``twist`` (core.command.Twist) into a Twist or TwistStamped message."""
    body = msg.twist if hasattr(msg, "header") else msg
    body.linear.x, body.linear.y, body.linear.z = map(float, twist.linear)
    body.angular.x, body.angular.y, body.angular.z = map(float, twist.angular)
    return msg


class BridgeAgent(RuntimeParams, AgentBase):
    """One agent per process; see the module doc."""

    mode = "bridge"

    def __init__(self, node, params, executor=None):
        super().__init__(node, params, executor)
        self.peers = PeerTable.of_agent(self)
        self.measured = None  # SimpleNamespace(x, rot, heard) of the last good measured pose
        self.holding = "no measured pose yet"
        self.zero_sent = False
        self.commands = 0
        pose_qos, cmd_qos = robot_qos()
        self.cmd_pub = node.create_publisher(twist_class(params["cmd_type"]), CMD_VEL, cmd_qos)
        node.create_subscription(
            pose_class(params["pose_type"]), MEASURED_POSE, self._measured_cb, pose_qos
        )
        self.watch_parameters()

    def _configure(self, p):
        if p["agents"] and len(p["agents"]) > 1:
            raise ParameterError("mode bridge: one agent per process (one robot each)")
        super()._configure(p)
        self.rebuild_system()  # refuses d >= 4 and second order before any topic exists

    def rebuild_system(self):
        self.system = bridge_system(self.model, self.layout.rows)

    def step_size(self, p):
        return 1.0 / p["rate"]

    # -- the robot's side ------------------------------------------------------------------------
    def _measured_cb(self, msg):
        pose = pose_of(msg)
        p, q = pose.position, pose.orientation
        got, reason = wire.pose_to_state(
            self.grp, self.model.dim, (p.x, p.y, p.z), (q.x, q.y, q.z, q.w)
        )
        if got is None:
            self.drops("measured_pose", reason)
            self._hold(f"measured pose refused ({reason})")
            self.measured = None
            return
        self.measured = SimpleNamespace(
            x=got[0] - self.scene.origin, rot=got[1], heard=time.monotonic()
        )

    def fresh_pose(self):
        """The measured pose if it is younger than pose_timeout, else None."""
        m = self.measured
        if m is None or time.monotonic() - m.heard > self.params["pose_timeout"]:
            return None
        return m

    def _hold(self, reason):
        """Publish one zero command and stay quiet until a fresh measured pose arrives."""
        if not self.zero_sent:
            self.cmd_pub.publish(self._message(ZERO))
            self.zero_sent = True
            self.log.warning(f"robot stopped: {reason}")
        self.holding = reason

    def _message(self, twist):
        msg = twist_class(self.params["cmd_type"])()
        if hasattr(msg, "header"):
            msg.header.stamp = self.node.get_clock().now().to_msg()
            msg.header.frame_id = (
                self.params["frame_id"] if self.params["command_frame"] == "world" else ""
            )
        return fill_twist(msg, twist)

    # -- one tick --------------------------------------------------------------------------------
    def tick(self, t):
        """Relay the measured pose and command the robot, or hold it (see the module doc)."""
        own = self.fresh_pose()
        if own is None:
            self._hold("no measured pose yet" if self.commands == 0 and self.measured is None
                       else f"measured pose older than {self.params['pose_timeout']:g} s")
            return
        gi, row = self.layout.owner[self.layout.local[0]]
        self.state = self._state_at(t, own)
        super().publish_state()
        request = SimpleNamespace(stage=self.state, fields=("rot", "x"))
        ensemble = self.peers.ensemble(request, self.peers.active())
        twist = command_from_ensemble(
            self.system,
            gi,
            row,
            ensemble,
            self.grp.to_matrices(own.rot)[0],
            self.params["command_frame"],
            self.params["max_linear_speed"],
            self.params["max_angular_speed"],
        )
        if not twist.finite:
            self._hold("non-finite command")
            return
        self.cmd_pub.publish(self._message(twist))
        self.zero_sent, self.holding = False, ""
        self.commands += 1
        self.saturated = twist.saturated

    def _state_at(self, t, own):
        gi = self.layout.owner[self.layout.local[0]][0]
        groups = [None] * len(self.model.groups)
        groups[gi] = GroupState(own.x[None], own.rot)
        return State(t, tuple(groups))

    def publish_state(self, final=False):
        """Relay the measured pose (if fresh) at the current stamp; never the scene's pose."""
        own = self.fresh_pose() if not final else self.measured
        if own is None:
            self._maybe_diagnostics()
            return
        self.state = self._state_at(max(0.0, self.state.t), own)
        super().publish_state(final)

    def on_pause(self, paused):
        """A pause commands zero at once, not at the next tick."""
        if paused:
            self._hold("paused")

    def diagnostic_note(self):
        note, extra = super().diagnostic_note()
        extra["commands"] = self.commands
        extra["holding"] = self.holding or "no"
        return (f"robot held: {self.holding}; " if self.holding else note), extra

    # -- running ---------------------------------------------------------------------------------
    _start_epoch = RealtimeAgent._start_epoch

    def loop(self):
        self.wait_for_discovery()
        start = self._start_epoch()
        next_tick = time.monotonic()
        while not self.stop_requested:
            self.apply_runtime()
            t = time.time() - start
            if t >= self.scene.t_end:
                break
            if self.paused:  # zero command; the measured pose still relayed to the peers
                self._hold("paused")
                self.state.t = max(t, 0.0)
                self.publish_state()
            elif t >= 0.0:
                self.tick(t)
                self.steps += 1
                self.rounds += 1
            self._maybe_diagnostics()
            next_tick += 1.0 / self.params["rate"]
            while time.monotonic() < next_tick and not self.stop_requested:
                self.spin_once(min(0.05, max(0.0, next_tick - time.monotonic())))
            if time.monotonic() - next_tick > 1.0 / self.params["rate"]:
                self.late_ticks += 1
                next_tick = time.monotonic()
        self._hold("the run ended")

    def run(self):
        self.loop()
        self.finished = True
        self._maybe_diagnostics(force=True)
        self.publish_state(final=True)
        self.flush_poses()
        return 0

    def destroy(self):
        """A shutdown (Ctrl-C) stops the robot too, if the middleware still lets us say so."""
        try:
            self._hold("shutdown")
        except Exception:  # noqa: BLE001 -- the context may already be gone; nothing to do
            pass
        super().destroy()

