"""A simulated robot: what a bridged agent drives when no hardware is at hand.

    ros2 run polymatch_ros robot --ros-args -r __ns:=/polymatch/robot_3 \\
        -p scene:=FILE -p agent:=3 [-p lag:=0.1 -p position_noise:=0.001 ...]

It receives ``cmd_vel`` (geometry_msgs/TwistStamped, or Twist with ``cmd_type:=twist``; world
or body frame), tracks it with a first-order actuator lag (time constant ``lag``) under the
speed limits, integrates its pose at ``rate`` Hz and publishes it with Gaussian noise on
``measured_pose`` (PoseStamped or nav_msgs/Odometry): the topics a real robot offers and
receives.  It starts at agent ``agent``'s initial pose of the scene.  A robot applies a command
for at most ``cmd_timeout`` s after it came (within a step too: the step's rest is braking) and
then stops by itself, as robot drivers do.

For a second-order scene (A-1) the robot is a double integrator: it receives ``cmd_accel``
(geometry_msgs/AccelStamped, world or body frame), its acceleration tracks the command with the
same lag, the speed limits still cut its velocity, and it publishes nav_msgs/Odometry
(``pose_type`` odometry) with the noisy pose and its actual twist (noise-free, in its body
frame ``base_link``, as Odometry specifies).  It starts at rest; its watchdog brings the
velocity to zero with the lag, as in the first-order mode.

With ``pose_log:=FILE`` it also writes one line per step to FILE (``POSE_LOG_COLUMNS``): the
wall time (s since the epoch), its true pose and the noisy pose it published; what no real
robot can offer, and what `polymatch bench bridge` measures the matching error with.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, TextIO

import numpy as np

from ...core.errors import ParameterError
from ...core.robots.formation import positions
from ...core.robots.robot_commands import saturate
from ...core.robots.unicycle import unicycle_step
from ..config.configs import RobotConfig, read_config
from ..config.resolve import resolve_robot
from ..process.shell import ros_main

if TYPE_CHECKING:
    from rclpy.node import Node




#: the columns of a ``pose_log`` line (world frame; quaternions x y z w)
POSE_LOG_COLUMNS = ("wall_time", "x", "y", "z", "qx", "qy", "qz", "qw",
                    "measured_x", "measured_y", "measured_z",
                    "measured_qx", "measured_qy", "measured_qz", "measured_qw")


class SimulatedRobot:
    """Pose (position p, rotation R, 3-D; planar robots stay in z = 0 about z) and the actual
    velocity (world frame) of a robot that tracks commanded twists (``step``) or accelerations
    (``accelerate``) with a first-order lag."""

    def __init__(self, position: Sequence[float] | np.ndarray, rotation: np.ndarray, planar: bool,
                 lag: float, max_linear: float, max_angular: float) -> None:
        from scipy.spatial.transform import Rotation

        self.p = np.zeros(3)
        self.p[: len(position)] = position
        rot = np.eye(3)
        rot[: len(rotation), : len(rotation)] = rotation
        self.rot = Rotation.from_matrix(rot)
        self.planar, self.lag = planar, lag
        self.max_linear, self.max_angular = max_linear, max_angular
        self.v, self.w = np.zeros(3), np.zeros(3)
        self.a, self.alpha = np.zeros(3), np.zeros(3)  # actual accelerations (second order)

    def _world(
        self, linear: np.ndarray, angular: np.ndarray, frame: str
    ) -> tuple[np.ndarray, np.ndarray]:
        """A commanded pair in the world frame, in the plane for a planar robot."""
        linear, angular = np.asarray(linear, float), np.asarray(angular, float)
        if frame == "body":
            mat = self.rot.as_matrix()
            linear, angular = mat @ linear, mat @ angular
        if self.planar:
            linear, angular = linear * [1, 1, 0], angular * [0, 0, 1]
        return linear, angular

    def _follow(self, dt: float) -> float:
        return 1.0 if self.lag == 0.0 else 1.0 - math.exp(-dt / self.lag)

    def _move(self, dt: float) -> None:
        from scipy.spatial.transform import Rotation

        self.p += self.v * dt
        self.rot = Rotation.from_rotvec(self.w * dt) * self.rot

    def step(self, dt: float, linear: np.ndarray, angular: np.ndarray,
             frame: str = "world") -> None:
        """Advance ``dt`` s towards the commanded (linear, angular) velocity."""
        linear, angular = self._world(linear, angular, frame)
        linear = saturate(linear, self.max_linear)[0]
        angular = saturate(angular, self.max_angular)[0]
        follow = self._follow(dt)
        self.v += follow * (linear - self.v)
        self.w += follow * (angular - self.w)
        self.a[:], self.alpha[:] = 0.0, 0.0
        self._move(dt)

    def accelerate(self, dt: float, linear: np.ndarray, angular: np.ndarray,
                   frame: str = "world") -> None:
        """Advance ``dt`` s as a double integrator whose acceleration tracks the commanded
        (linear, angular) acceleration; the speed limits cut the velocity."""
        linear, angular = self._world(linear, angular, frame)
        follow = self._follow(dt)
        self.a += follow * (linear - self.a)
        self.alpha += follow * (angular - self.alpha)
        self.v = saturate(self.v + self.a * dt, self.max_linear)[0]
        self.w = saturate(self.w + self.alpha * dt, self.max_angular)[0]
        self._move(dt)

    def roll(self, dt: float, v: float, omega: float) -> None:
        """Advance ``dt`` s as a differential-drive base (planar): forward speed and turn rate
        track the commanded v (body linear.x) and omega (angular.z) with the lag; the pose moves
        on the exact arc; it never moves sideways."""
        from scipy.spatial.transform import Rotation

        follow = self._follow(dt)
        mat = self.rot.as_matrix()
        heading = math.atan2(mat[1, 0], mat[0, 0])
        speed = float(mat[:, 0] @ self.v) + follow * (v - float(mat[:, 0] @ self.v))
        turn = self.w[2] + follow * (omega - self.w[2])
        p, heading = unicycle_step(self.p, heading, speed, turn, dt)
        self.p[:2] = p
        self.rot = Rotation.from_rotvec([0.0, 0.0, heading])
        self.v = speed * np.array([math.cos(heading), math.sin(heading), 0.0])
        self.w = np.array([0.0, 0.0, turn])

    def body_twist(self) -> tuple[np.ndarray, np.ndarray]:
        """(linear, angular) velocity in the robot's own frame (an Odometry message's twist)."""
        mat = self.rot.as_matrix()
        return mat.T @ self.v, mat.T @ self.w

    def measure(
        self, rng: np.random.Generator, position_noise: float, angle_noise: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """(position, quaternion xyzw) with Gaussian noise."""
        from scipy.spatial.transform import Rotation

        p = self.p + rng.normal(0.0, position_noise, 3) * ([1, 1, 0] if self.planar else 1)
        turn = rng.normal(0.0, angle_noise, 3) * ([0, 0, 1] if self.planar else 1)
        return p, (Rotation.from_rotvec(turn) * self.rot).as_quat()


class RobotNode:
    """The simulated robot as a node (``run()`` until Ctrl-C or SIGTERM)."""

    def __init__(self, node: Node, config: RobotConfig) -> None:
        from ...core.scenes.scene import load_scene, resolve_scene_path
        from ..agents.bridge import (
            CMD_ACCEL,
            CMD_VEL,
            MEASURED_POSE,
            command_class,
            pose_class,
            robot_qos,
        )

        self.node, self.config = node, config
        scene = load_scene(resolve_scene_path(config.scene or ""))
        model = scene.model
        if config.agent >= model.n_agents:
            raise ParameterError(
                f"parameter 'agent': {config.agent} is not in the scene "
                f"(0..{model.n_agents - 1})"
            )
        if model.dim > 3:
            raise ParameterError(f"robot: d = {model.dim}; robots live in 2-D or 3-D")
        gi, row = model.group_of(config.agent)
        gs = scene.initial.groups[gi]
        assert gs is not None  # the scene's initial state has every group
        rot = model.rotations.to_matrices(model.rotations.take(gs.rot, [row]))[0]
        self.robot = SimulatedRobot(
            positions(gs.x[[row]], scene.formation, scene.origin, np.array([config.agent]))[0],
            rot, model.dim == 2, config.lag,
            config.max_linear_speed, config.max_angular_speed,
        )
        self.second_order = model.order == 2
        if self.second_order and config.pose_type != "odometry":
            raise ParameterError("robot: a second-order scene publishes its velocity: "
                                 "pose_type:=odometry (nav_msgs/Odometry)")
        self.rng = np.random.default_rng(config.seed)
        self.command = (np.zeros(3), np.zeros(3), -math.inf)
        pose_qos, cmd_qos = robot_qos()
        self.pose_msg = pose_class(config.pose_type)
        self.pose_pub = node.create_publisher(self.pose_msg, MEASURED_POSE, 10)
        node.create_subscription(command_class(model.order, config.cmd_type),
                                 CMD_ACCEL if self.second_order else CMD_VEL, self._command,
                                 cmd_qos)
        self.pose_log: TextIO | None = None
        if config.pose_log:
            try:
                self.pose_log = open(config.pose_log, "w", encoding="utf-8", buffering=1)
            except OSError as exc:
                raise ParameterError(f"parameter 'pose_log': {exc.strerror}: "
                                     f"{config.pose_log}") from None
            self.pose_log.write("# " + " ".join(POSE_LOG_COLUMNS) + "\n")

    def _command(self, msg: Any) -> None:
        body = msg.twist if hasattr(msg, "twist") else msg.accel if hasattr(msg, "accel") else msg
        lin, ang = body.linear, body.angular
        values = np.array([lin.x, lin.y, lin.z, ang.x, ang.y, ang.z])
        if np.all(np.isfinite(values)):  # a robot ignores a corrupt command
            self.command = (values[:3], values[3:], time.monotonic())

    def _publish(self) -> None:
        p, q = self.robot.measure(
            self.rng, self.config.position_noise, self.config.angle_noise
        )
        msg = self.pose_msg()
        msg.header.stamp = self.node.get_clock().now().to_msg()
        msg.header.frame_id = self.config.frame_id
        pose = msg.pose.pose if hasattr(msg, "child_frame_id") else msg.pose
        if hasattr(msg, "child_frame_id"):
            msg.child_frame_id = "base_link"
            twist = msg.twist.twist
            linear, angular = self.robot.body_twist()
            twist.linear.x, twist.linear.y, twist.linear.z = map(float, linear)
            twist.angular.x, twist.angular.y, twist.angular.z = map(float, angular)
        pose.position.x, pose.position.y, pose.position.z = map(float, p)
        o = pose.orientation
        o.x, o.y, o.z, o.w = map(float, q)
        self.pose_pub.publish(msg)
        if self.pose_log is not None:
            true = (*self.robot.p, *self.robot.rot.as_quat())
            values = (time.time(), *true, *p, *q)
            self.pose_log.write(" ".join(f"{v:.17g}" for v in values) + "\n")

    def run(self) -> int:
        import rclpy

        period = 1.0 / self.config.rate
        last = time.monotonic()
        while rclpy.ok():
            rclpy.spin_once(self.node, timeout_sec=max(0.0, last + period - time.monotonic()))
            now = time.monotonic()
            if now - last < period:
                continue
            self._advance(min(now - last, 5 * period), now)
            last = now
            self._publish()
        return 0

    def _advance(self, dt: float, now: float) -> None:
        """Move the robot over the ``dt`` s before ``now`` (monotonic): the last command while
        it is younger than ``cmd_timeout``, then the watchdog's stop (velocity to zero with the
        lag) for the rest of the step."""
        linear, angular, heard = self.command
        valid = min(dt, max(0.0, heard + self.config.cmd_timeout - (now - dt)))
        if valid > 0.0:
            frame = self.config.command_frame
            if self.second_order:
                self.robot.accelerate(valid, linear, angular, frame)
            elif self.config.drive == "unicycle":
                self.robot.roll(valid, linear[0], angular[2])
            else:
                self.robot.step(valid, linear, angular, frame)
        if dt - valid > 0.0:
            self.robot.step(dt - valid, np.zeros(3), np.zeros(3))

    def destroy(self) -> None:
        if self.pose_log is not None:
            self.pose_log.close()
        self.node.destroy_node()


def make_robot(argv: list[str] | None = None) -> RobotNode:
    from rclpy.node import Node

    node = Node("robot", automatically_declare_parameters_from_overrides=False)
    return RobotNode(node, read_config(node, RobotConfig, resolve_robot))


def main(args: list[str] | None = None) -> int:
    return ros_main(make_robot, "robot", args)


if __name__ == "__main__":
    sys.exit(main())
