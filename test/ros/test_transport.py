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


def _fast_dds_library():
    """The libfastrtps that rmw_fastrtps_cpp loads, found beside this interpreter's ROS."""
    import pathlib
    import sys

    found = sorted(pathlib.Path(sys.prefix, "lib").glob("libfastrtps.so.*"))
    return found[-1] if found else None


def test_the_wheels_fast_dds_has_no_security_plugins():
    """docs/guide/hosts-and-graphs.md, "Security on the wire": the PyPI Fast DDS carries none of
    the DDS Security builtin plugins (authentication PKI-DH, access control, AES-GCM-GMAC) and
    says "security is disabled"; a wheel that brings them makes this fail, and the guide's
    advice wants updating."""
    import pytest

    library = _fast_dds_library()
    if library is None:
        pytest.skip("Fast DDS is not installed as a PyPI wheel here")
    data = library.read_bytes()
    assert b"but security is disabled" in data
    for plugin in (b"PKI-DH", b"Access-Permissions", b"AES-GCM-GMAC"):
        assert plugin not in data, plugin
