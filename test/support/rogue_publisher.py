"""A rogue publisher for the robustness test: floods one agent's topics with bad messages.

    python test/support/rogue_publisher.py ENSEMBLE AGENT SECONDS

Sends, at ~100 Hz each: PoseStamped with NaN positions, PoseStamped with a quaternion of
norm 2, and lockstep stage messages with NaN data, a foreign run id, or no header.  It is started
by
the test in the test's own ROS domain (loopback discovery) under `timeout`.
"""

import math
import sys
import time

import rclpy
from geometry_msgs.msg import PoseStamped
from rclpy.node import Node
from std_msgs.msg import Float64MultiArray

from polymatch_ros.ros import wire


def main():
    ensemble, agent, seconds = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
    rclpy.init()
    node = Node("rogue")
    qos = wire.qos_profiles()
    pose = node.create_publisher(PoseStamped, wire.full_name(ensemble, "pose", agent), qos["pose"])
    stage = node.create_publisher(Float64MultiArray, wire.full_name(
        ensemble, "stage", agent), qos["stage"])
    end = time.monotonic() + seconds
    k = 0
    while time.monotonic() < end:
        p = PoseStamped()
        p.header.frame_id = "world"
        p.header.stamp.sec = k
        if k % 2:
            p.pose.position.x = math.nan
            p.pose.orientation.w = 1.0
        else:
            p.pose.orientation.w = 2.0                      # quaternion far from unit norm
        pose.publish(p)
        fields = {"x": [0.0, 0.0], "rot": [math.nan if k % 2 else 0.3]}
        msg = wire.encode_stage(Float64MultiArray(), 12345 if k %
                                2 == 0 else 0, agent, k, 0, 0, 0.0, fields)
        stage.publish(msg)
        junk = Float64MultiArray()                          # no header at all
        junk.data = [1.0, 2.0]
        stage.publish(junk)
        k += 1
        if k == 20:
            print("rogue: flooding", flush=True)           # the test starts the run after this
        rclpy.spin_once(node, timeout_sec=0.01)
    print(f"rogue: sent {k} bad poses and {k} bad stage messages", flush=True)
    node.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    main()
