"""Bridge: an agent that drives a robot.  Its state is the robot's measured pose; it commands the
robot's velocity with the first-order model (A-2), or its acceleration with the second-order
model (A-1).

    ros2 run polymatch_ros agent --ros-args -r __ns:=/polymatch -r __node:=agent_3 \\
        -p scene:=FILE -p agent:=3 -p mode:=bridge \\
        -r measured_pose:=/robot3/odom -p pose_type:=odometry -r cmd_vel:=/robot3/cmd_vel

Every tick (``rate`` Hz) the agent takes its own pose from ``measured_pose`` (PoseStamped or
nav_msgs/Odometry), relays it on ``agent_<i>/pose`` for its peers and the monitor (stamped
with the seconds since the ensemble's start), and publishes on ``cmd_vel`` (Twist or
TwistStamped) linear = xbar_i' and angular = the axial vector of W_i of (A-2) against the
peers' latest poses (``core.robots.robot_commands``), saturated, in the world or the robot's body
frame.

Second-order scene: ``measured_pose`` must be nav_msgs/Odometry (``pose_type:=odometry``): its
twist, in the child (body) frame as Odometry specifies, turned into the world frame with the
measured orientation, is the agent's own xbar_i' and W_i (relayed on ``agent_<i>/twist``;
the peers' velocities are not needed: (A-1)'s right-hand side has none).  The agent publishes
geometry_msgs/AccelStamped on ``cmd_accel``: linear = xbar_i'' and angular = the axial vector of
W_i' of (A-1), saturated by ``max_linear_accel`` and ``max_angular_accel``.

Safety: a measured pose older than ``pose_timeout``, a non-finite pose or command, and the
end of the run (t_end, 'stop', shutdown) publish one zero command; the agent then stays quiet
(no command, no relayed pose: its peers drop it after their peer timeout) until a fresh pose
arrives.  A pause (``control``) publishes one zero command at once and keeps relaying the
measured pose, so that the peers keep the robot; resume goes on at the next tick.  The reason
is in the diagnostics.

A second-order robot keeps its velocity under a zero acceleration, so a pause and a non-finite
command brake it instead: every tick, while its fresh measured velocity is above
``core.robots.robot_commands.STILL``, the damped stop of (A-1) without coupling (a = -(gamma/m) v,
alpha =
-(gamma/m) omega); at rest, one zero command and quiet.  A stale pose, the end of the run and a
shutdown leave no measured velocity (or no agent) to close that loop, and a held braking
acceleration would drive the robot backwards after m/gamma s: they publish one zero
acceleration, which adds no energy; the robot's own command watchdog stops it from there.
"""

from __future__ import annotations

import time
from types import SimpleNamespace
from typing import TYPE_CHECKING, Any

import numpy as np

from ...core.errors import ParameterError
from ...core.model import GroupState, State
from ...core.robots.robot_commands import (
    ZERO,
    brake_command,
    bridge_system,
    is_still,
    rotation3,
)
from ...core.robots.safety import PeerSight
from ...core.robots.shaping import shaper_for
from .. import wire
from ..config.runtime_params import RuntimeParams
from .agent_base import AgentBase
from .realtime import PeerTable, RealtimeAgent

if TYPE_CHECKING:
    from rclpy.executors import Executor
    from rclpy.node import Node
    from rclpy.qos import QoSProfile

    from ...core.robots.robot_commands import Twist
    from ..config.resolve import ResolvedAgent
    from .realtime import Ensemble

#: relative names: remap them to a robot's topics (``-r cmd_vel:=/robot3/cmd_vel``)
MEASURED_POSE, CMD_VEL, CMD_ACCEL = "measured_pose", "cmd_vel", "cmd_accel"


def robot_qos() -> tuple[QoSProfile, QoSProfile]:
    """Measured poses: the newest only, BEST_EFFORT (matches RELIABLE and BEST_EFFORT odometry
    publishers); commands: RELIABLE, depth 10 (what teleop tools and robot drivers use)."""
    from rclpy.qos import QoSProfile, qos_profile_sensor_data

    return qos_profile_sensor_data, QoSProfile(depth=10)


def pose_class(pose_type: str) -> type:
    if pose_type == "odometry":
        from nav_msgs.msg import Odometry

        return Odometry
    from geometry_msgs.msg import PoseStamped

    return PoseStamped


def twist_class(cmd_type: str) -> type:
    from geometry_msgs.msg import Twist, TwistStamped

    return TwistStamped if cmd_type == "twist_stamped" else Twist


def command_class(order: int, cmd_type: str) -> type:
    """The command message: AccelStamped (second order) or Twist / TwistStamped (``cmd_type``)."""
    if order == 2:
        from geometry_msgs.msg import AccelStamped

        return AccelStamped
    return twist_class(cmd_type)


def pose_of(msg: Any) -> Any:
    """The geometry_msgs/Pose inside a PoseStamped or an Odometry message."""
    return msg.pose.pose if hasattr(msg, "child_frame_id") else msg.pose


def fill_twist(msg: Any, twist: Twist) -> Any:
    """Write ``twist`` (``core.robots.robot_commands.Twist``) into a Twist, TwistStamped or
    AccelStamped message."""
    body = msg.twist if hasattr(msg, "twist") else msg.accel if hasattr(msg, "accel") else msg
    body.linear.x, body.linear.y, body.linear.z = map(float, twist.linear)
    body.angular.x, body.angular.y, body.angular.z = map(float, twist.angular)
    return msg


class BridgeAgent(RuntimeParams, AgentBase):
    """One agent per process; see the module doc."""

    mode = wire.Mode.BRIDGE

    def __init__(
        self, node: Node, resolved: ResolvedAgent, executor: Executor | None = None
    ) -> None:
        super().__init__(node, resolved, executor)
        self.peers = PeerTable.of_agent(self)
        # SimpleNamespace(x, rot, heard) of the last good measured pose
        self.measured: SimpleNamespace | None = None
        self.holding = "no measured pose yet"
        self.zero_sent = False
        self.commands = 0
        self.epoch = time.time()  # t = 0 of the ensemble's clock (``loop``)
        pose_qos, cmd_qos = robot_qos()
        self.cmd_class = command_class(self.model.order, self.config.cmd_type)
        topic = CMD_ACCEL if self.model.order == 2 else CMD_VEL
        self.cmd_pub = node.create_publisher(self.cmd_class, topic, cmd_qos)
        node.create_subscription(
            pose_class(self.config.pose_type), MEASURED_POSE, self._measured_cb, pose_qos
        )
        self.watch_parameters()

    def _configure(self, resolved: ResolvedAgent) -> None:
        config = resolved.config
        if len(config.hosted) > 1:
            raise ParameterError("mode bridge: one agent per process (one robot each)")
        super()._configure(resolved)
        self.rebuild_system()  # refuses d >= 4 and undamped second order before any topic
        self.shaper = shaper_for(self.scene, self.layout.local[0], config)
        if self.model.order == 2 and config.pose_type != "odometry":
            raise ParameterError(
                "mode bridge: a second-order scene needs the robot's velocity: "
                "pose_type:=odometry (nav_msgs/Odometry)"
            )

    def rebuild_system(self) -> None:
        self.system = bridge_system(self.model, self.layout.rows)

    # -- the robot's side ------------------------------------------------------------------------
    def _measured_cb(self, msg: Any) -> None:
        pose = pose_of(msg)
        p, q = pose.position, pose.orientation
        got, reason = wire.pose_to_state(
            self.grp, self.model.dim, (p.x, p.y, p.z), (q.x, q.y, q.z, q.w)
        )
        if got is None:
            self.drops("measured_pose", reason)  # type: ignore[arg-type]  # with None
            self._hold(f"measured pose refused ({reason})")
            self.measured = None
            return
        velocity: tuple[Any, Any, Any] = (
            self._measured_velocity(msg, got[1]) if self.model.order == 2 else (None,) * 3
        )
        if velocity[0] is None and self.model.order == 2:
            self.drops("measured_pose", velocity[2])
            self._hold(f"measured velocity refused ({velocity[2]})")
            self.measured = None
            return
        self.measured = SimpleNamespace(
            x=self.shaper.state_x(got[0], self.grp.to_matrices(got[1])[0]), rot=got[1],
            v=velocity[0], w=velocity[1],
            heard=time.monotonic()
        )

    def _measured_velocity(
        self, msg: Any, rot: np.ndarray
    ) -> tuple[np.ndarray | None, np.ndarray | None, str | None]:
        """(xbar_i', W_i (one algebra row), None) in the world frame from an Odometry twist (in
        its child frame, the body), or (None, None, reason)."""
        tw = msg.twist.twist
        r3 = rotation3(self.grp.to_matrices(rot)[0])
        linear = r3 @ [tw.linear.x, tw.linear.y, tw.linear.z]
        angular = r3 @ [tw.angular.x, tw.angular.y, tw.angular.z]
        got, reason = wire.twist_to_state(self.grp, self.model.dim, linear, angular)
        return (None, None, reason) if got is None else (got[0], got[1], None)

    def fresh_pose(self) -> SimpleNamespace | None:
        """The measured pose if it is younger than pose_timeout, else None."""
        m = self.measured
        if m is None or time.monotonic() - m.heard > self.config.pose_timeout:
            return None
        return m

    def _hold(self, reason: str, brake: bool = False) -> None:
        """Publish one zero command and stay quiet until a fresh measured pose arrives;
        ``brake``: a moving second-order robot is braked first (``_brake``)."""
        if brake and self.model.order == 2 and self._brake(reason):
            return
        if not self.zero_sent:
            self.cmd_pub.publish(self._message(ZERO))
            self.zero_sent = True
            self.log.warning(f"robot stopped: {reason}")
        self.holding = reason

    def _brake(self, reason: str) -> bool:
        """Command the damped stop (``core.robots.robot_commands.brake_command``) while the fresh
        measured
        velocity says the robot moves: True; False when it is at rest or not measured."""
        own = self.fresh_pose()
        if own is None:
            return False
        skew = self.grp.algebra_to_skew(own.w)[0]
        if is_still(own.v, skew):
            return False
        if self.holding != reason:
            self.log.warning(f"robot braking: {reason}")
        c = self.config
        self.cmd_pub.publish(self._message(brake_command(
            self.model, own.v, skew, self.grp.to_matrices(own.rot)[0], c.command_frame,
            c.max_linear_accel, c.max_angular_accel,
        )))
        self.zero_sent, self.holding = False, reason
        return True

    def _message(self, twist: Twist) -> Any:
        msg = self.cmd_class()
        if hasattr(msg, "header"):
            msg.header.stamp = self.node.get_clock().now().to_msg()
            msg.header.frame_id = (
                self.config.frame_id if self.config.command_frame == "world" else ""
            )
        return fill_twist(msg, twist)

    # -- one tick --------------------------------------------------------------------------------
    def tick(self, t: float) -> None:
        """Relay the measured pose and command the robot, or hold it (see the module doc)."""
        own = self.fresh_pose()
        if own is None:
            self._hold("no measured pose yet" if self.commands == 0 and self.measured is None
                       else f"measured pose older than {self.config.pose_timeout:g} s")
            return
        gi, row = self.layout.owner[self.layout.local[0]]
        self.state = self._state_at(t, own)
        self.checkpoint.write(self.steps, t, self.state)  # what --save keeps if the run ends now
        super().publish_state()
        fields = ("rot", "x", "v") if self.model.order == 2 else ("rot", "x")
        request = SimpleNamespace(stage=self.state, fields=fields)
        heard = self.peers.in_range(self.peers.active(), self.state)  # a radio: peers in range
        ensemble = self.peers.ensemble(request,  # type: ignore[arg-type]
                                       self.peers.peer_rows(heard))
        twist = self._command(gi, row, ensemble, own, heard)
        if not twist.finite:
            self._hold("non-finite command", brake=True)
            return
        self.cmd_pub.publish(self._message(twist))
        self.zero_sent, self.holding = False, ""
        self.commands += 1
        self.saturated = twist.saturated

    def _command(
        self, gi: int, row: int, ensemble: Ensemble, own: SimpleNamespace, heard: list[int]
    ) -> Twist:
        """The twist (A-2) or the acceleration (A-1) of this agent against ``ensemble``."""
        # formation, safety filter, drive: core.robots.shaping
        rot = self.grp.to_matrices(own.rot)[0]
        sight = self._peer_sight() if self.shaper.safety is not None else None
        return self.shaper.command(self.system, gi, row, ensemble, own, rot, self.state.t,
                                   self.config, sight, time.monotonic() - own.heard)

    def _peer_sight(self) -> PeerSight:
        """Every peer ever heard, silent ones too (a robot dropped from the sums is still in
        the room), with its stamp's age now on the ensemble's clock (the filter's peers)."""
        known = [(a, e) for a, e in self.peers.latest.items() if e.x is not None]
        now = time.time() - self.epoch
        x = np.array([e.x for _, e in known]).reshape(len(known), self.model.dim)
        ages = np.array([now - e.t for _, e in known])
        v = None
        if self.model.order == 2:
            v = np.array([e.v if e.v is not None else np.zeros(self.model.dim)
                          for _, e in known]).reshape(len(known), self.model.dim)
        return self.shaper.sight([a for a, _ in known], x, ages, v)

    def _state_at(self, t: float, own: SimpleNamespace) -> State:
        gi = self.layout.owner[self.layout.local[0]][0]
        groups: list[GroupState | None] = [None] * len(self.model.groups)
        v = None if own.v is None else own.v[None]
        groups[gi] = GroupState(own.x[None], own.rot, v, own.w)
        return State(t, tuple(groups))

    def publish_state(self, final: bool = False) -> None:
        """Relay the measured pose (if fresh) at the current stamp; never the scene's pose."""
        own = self.fresh_pose() if not final else self.measured
        if own is None:
            self._maybe_diagnostics()
            return
        self.state = self._state_at(max(0.0, self.state.t), own)
        super().publish_state(final)

    def on_pause(self, paused: bool) -> None:
        """A pause commands zero at once, not at the next tick."""
        if paused:
            self._hold("paused", brake=True)

    def diagnostic_note(self) -> tuple[str, dict[str, Any]]:
        note, extra = super().diagnostic_note()
        extra["commands"] = self.commands
        extra["holding"] = self.holding or "no"
        extra.update(self.shaper.note())
        if self.shaper.watch.deadlocked and not self.holding:
            note = "deadlock: the safety filter holds the robot short of its place; " + note
        if self.peers.in_range_count is not None:
            extra["peers_in_range"] = self.peers.in_range_count
        return (f"robot held: {self.holding}; " if self.holding else note), extra

    # -- running ---------------------------------------------------------------------------------
    _start_epoch = RealtimeAgent._start_epoch

    def loop(self) -> None:
        self.wait_for_discovery()
        start = self.epoch = self._start_epoch()
        next_tick = time.monotonic()
        while not self.stop_requested:
            self.apply_runtime()
            t = time.time() - start
            if t >= self.scene.t_end:
                break
            if self.paused:  # zero command (or braking); the measured pose still relayed
                self._hold("paused", brake=True)
                self.state.t = max(t, 0.0)
                self.publish_state()
            elif t >= 0.0:
                self.tick(t)
                self.steps += 1
                self.rounds += 1
            self._maybe_diagnostics()
            next_tick += 1.0 / self.config.rate
            while time.monotonic() < next_tick and not self.stop_requested:
                self.spin_once(min(0.05, max(0.0, next_tick - time.monotonic())))
            if time.monotonic() - next_tick > 1.0 / self.config.rate:
                self.late_ticks += 1
                next_tick = time.monotonic()
        self._hold("the run ended")

    def run(self) -> int:
        self.loop()
        self.finished = True
        self._maybe_diagnostics(force=True)
        self.publish_state(final=True)
        self.flush_poses()
        return 0

    def destroy(self) -> None:
        """A shutdown (Ctrl-C) stops the robot too, if the middleware still lets us say so."""
        try:
            self._hold("shutdown")
        except Exception:  # noqa: BLE001 -- the context may already be gone; nothing to do
            pass
        self.peers.destroy()
        super().destroy()

    def release(self) -> None:
        """The peers' lean node (lifecycle cleanup)."""
        self.peers.destroy()

