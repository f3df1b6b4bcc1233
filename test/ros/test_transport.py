"""The transport every polymatch process uses on loopback: UDPv4 on 127.0.0.1, no shared memory.

Fast DDS 2.14's shared-memory transport can leave a peer's port broken for good (two live
processes stop hearing each other); under ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST the
FASTDDS_BUILTIN_TRANSPORTS variable does not remove it, so the shipped profile names UDPv4
itself.  A participant that listens on a shared-memory port has a ``dds.shm.<port>`` thread.
"""

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
