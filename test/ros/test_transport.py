"""The transport every polymatch process uses on loopback: UDPv4 on 127.0.0.1, no shared memory.

Fast DDS 2.14's shared-memory transport can leave a peer's port broken for good (two live
processes stop hearing each other); under ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST the
FASTDDS_BUILTIN_TRANSPORTS variable does not remove it, so the shipped profile names UDPv4
itself.  A participant that listens on a shared-memory port has a ``dds.shm.<port>`` thread.
"""

import ast
import re
import textwrap

from ros_harness import PY, needs_ros

pytestmark = needs_ros

THREADS = textwrap.dedent("""
    import os, time, rclpy
    rclpy.init()
    node = rclpy.create_node("transport_probe")
    pub = node.create_publisher(__import__("std_msgs.msg").msg.String, "probe", 10)
    time.sleep(0.5)
    names = [open(f"/proc/self/task/{t}/comm").read().strip()
             for t in os.listdir("/proc/self/task")]
    print("THREADS", " ".join(sorted(n for n in names if n.startswith("dds."))), flush=True)
    node.destroy_node()
    rclpy.shutdown()
""")


def _dds_threads(ros):
    proc = ros.start([PY, "-c", THREADS], timeout=30, name="transport_probe")
    assert ros.wait(proc, 40) == 0, ros.output(proc)
    line = [x for x in ros.output(proc).splitlines() if x.startswith("THREADS")]
    assert line, ros.output(proc)
    return line[0].split()[1:]


def test_loopback_participants_listen_on_udp_only_never_on_shared_memory(ros):
    threads = _dds_threads(ros)
    assert any(re.fullmatch(r"dds\.udp\.\d+", t) for t in threads), threads
    assert not [t for t in threads if re.fullmatch(r"dds\.shm\.\d+", t)], threads


EVENTS = textwrap.dedent("""
    import rclpy
    from polymatch_ros.ros import wire
    rclpy.init()
    node = rclpy.create_node("events_probe")
    bare = len(list(node.waitables))  # the node's own rosout and parameter-event writers'
    per_agent = [wire.publisher(node, "state", 2, 0), wire.publisher(node, "pose", 2, 0),
                 wire.subscription(node, "final_state", print, 2, 0)]
    own = [wire.publisher(node, "status"), wire.subscription(node, "control", print)]
    print("EVENTS", [len(e.event_handlers) for e in per_agent],
          [len(e.event_handlers) for e in own], len(list(node.waitables)) - bare,
          flush=True)
    node.destroy_node()
    rclpy.shutdown()
""")


def test_per_agent_topics_carry_no_qos_event_handlers(ros):
    """rclpy's executor walks every event handler of a node's endpoints on each spin, with a
    list-membership test per handler: a process of 256 agents spent a quarter of its time there.
    Per-agent topics get none; a process's own topics keep rclpy's QoS warnings."""
    proc = ros.start([PY, "-c", EVENTS], timeout=60, name="events")
    assert ros.wait(proc, 70) == 0, ros.output(proc)
    line = re.search(r"^EVENTS (\[.*?\]) (\[.*?\]) (\d+)$", ros.output(proc), re.M)
    assert line, ros.output(proc)
    per_agent, own = ast.literal_eval(line.group(1)), ast.literal_eval(line.group(2))
    waitables = int(line.group(3))
    assert per_agent == [0, 0, 0] and min(own) > 0, line.group(0)
    assert waitables == sum(own), line.group(0)  # what the executor walks: the own topics'

