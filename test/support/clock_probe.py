"""A ``use_sim_time`` reader for the /clock test: a plain rclpy node, nothing of polymatch_ros.

    python test/support/clock_probe.py POSE_TOPIC END_NS BOUND_S

Prints ``CLOCK <ns> <monotonic s>`` for every /clock message (and when it came) and
``POSE <ns>`` for every stamp on POSE_TOPIC (geometry_msgs/PoseStamped), until /clock reaches
END_NS (then, once the pose of END_NS came and its own clock, which follows /clock, shows it,
or 5 s later, ``NOW <ns> <ros time active>``: that clock) or BOUND_S seconds pass (exit 3).
"""

import sys
import time

import rclpy
from geometry_msgs.msg import PoseStamped
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock


def main():
    topic, end_ns, bound = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
    rclpy.init()
    node = Node("clock_probe", parameter_overrides=[
        Parameter("use_sim_time", Parameter.Type.BOOL, True)])
    seen = []

    def on_clock(msg):
        ns = msg.clock.sec * 10**9 + msg.clock.nanosec
        seen.append(ns)
        print(f"CLOCK {ns} {time.monotonic():.4f}", flush=True)

    poses = []

    def on_pose(msg):
        poses.append(msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec)
        print(f"POSE {poses[-1]}", flush=True)

    # as rclpy's time source reads /clock: newest only, best effort
    node.create_subscription(Clock, "/clock", on_clock,
                             QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT))
    node.create_subscription(PoseStamped, topic, on_pose, QoSProfile(depth=1000))
    deadline = time.monotonic() + bound
    while not (seen and seen[-1] >= end_ns):
        if time.monotonic() > deadline:
            print("TIMEOUT", flush=True)
            return 3
        rclpy.spin_once(node, timeout_sec=0.1)
    # the last step's pose comes on another writer than its /clock, and the node's own clock
    # follows /clock through rclpy's time source, a reader of its own whose callback may still
    # be waiting its turn: wait for both (5 s at most)
    clock = node.get_clock()
    last = time.monotonic() + 5.0
    while (end_ns not in poses or clock.now().nanoseconds < end_ns) and \
            time.monotonic() < last:
        rclpy.spin_once(node, timeout_sec=0.05)
    print(f"NOW {clock.now().nanoseconds} {clock.ros_time_is_active}", flush=True)
    node.destroy_node()
    rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
