"""A reader in a user's second shell, for the test of a run in the user's ROS graph: plain
rclpy in the environment it is started with (nothing of polymatch's set-up), it reads
``/<ensemble>/diameter`` and the monitor's run records on ``/<ensemble>/status`` and prints
one JSON line per message, until it has COUNT of each (exit 0) or BOUND s passed (exit 3).

    python test/support/graph_reader.py [--ensemble NAME] [--count COUNT]

Each topic's type is read from the graph (a run record is a JSON string or a typed message).
"""

import argparse
import importlib
import json
import os
import sys
import time

import rclpy
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

BOUND = 90.0


def emit(**line):
    print(json.dumps(line), flush=True)


def message_class(type_name):
    pkg, _, name = type_name.partition("/msg/")
    return getattr(importlib.import_module(f"{pkg}.msg"), name)


def record_role(msg):
    """The role of a run record, a JSON string (std_msgs/String) or a typed message."""
    if hasattr(msg, "role"):
        return msg.role
    try:
        return json.loads(msg.data).get("role")
    except (ValueError, AttributeError):
        return None


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--ensemble", default="polymatch")
    ap.add_argument("--count", type=int, default=3)
    args = ap.parse_args()
    emit(domain=os.environ.get("ROS_DOMAIN_ID"),
         range=os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE"))
    rclpy.init(args=[])
    node = Node(f"graph_reader_{os.getpid()}")
    seen = {"diameter": 0, "status": 0}
    deadline = time.monotonic() + BOUND
    qos = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)

    def reader(key):
        def take(msg):
            seen[key] += 1
            if key == "diameter":
                emit(diameter=msg.data)
            else:
                emit(status=record_role(msg))
        return take

    for key in seen:
        topic = f"/{args.ensemble}/{key}"
        infos = []
        while not infos:
            if time.monotonic() > deadline:
                emit(timeout=f"no publisher on {topic}")
                return 3
            infos = node.get_publishers_info_by_topic(topic)
            rclpy.spin_once(node, timeout_sec=0.1)
        node.create_subscription(message_class(infos[0].topic_type), topic, reader(key), qos)
    while min(seen.values()) < args.count:
        if time.monotonic() > deadline:
            emit(timeout=f"heard {seen}")
            return 3
        rclpy.spin_once(node, timeout_sec=0.1)
    emit(done=seen)
    return 0


if __name__ == "__main__":
    sys.exit(main())
