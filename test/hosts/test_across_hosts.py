"""`polymatch run` across hosts: --only, --no-monitor, --discovery (the options' checks:
test/contract/test_host_options.py).

The three-host case runs one lockstep ensemble of 12 agents split 4/4/4 over three network
namespace hosts (netns_hosts.py) with multicast discovery on their private subnet, data over
UDPv4 only (shared memory would bypass the network between the namespaces).  The host with the
monitor prints the summary from the final poses of all 12 agents; its lockstep deviation and
the saved poses must match the centralised simulation to 1e-9, and tcpdump on the root
namespace must see no DDS packet.  The one-host case runs through a discovery server that the
runner starts on 127.0.0.1 and ends by PID.
"""

import os
import re
import sys

import pytest
from host_runs import check_lockstep_on_hosts, run_on_hosts, three_hosts
from ros_harness import needs_ros, scene_path

from benchmarks.hosts.runs import (
    lockstep_argvs,
)

SCENE = "mixed_triangles_tetrahedra"        # 12 agents (6 triangles, 6 tetrahedra)


# -- one host, a discovery server of the run -------------------------------------------------

def _server_processes(port):
    found = []
    for cmdline in os.listdir("/proc"):
        if not cmdline.isdigit():
            continue
        try:
            with open(f"/proc/{cmdline}/cmdline", "rb") as fh:
                argv = fh.read().split(b"\0")
        except OSError:
            continue
        if b"polymatch_ros.ros.network.discovery_server" in argv and str(port).encode() in argv:
            found.append(int(cmdline))
    return found


@needs_ros
def test_run_through_its_own_discovery_server_converges(ros):
    # two agents per process: four clients of the server, converging in a third of the time
    proc = ros.start([sys.executable, "-m", "polymatch_ros.cli", "run", "congruent_triangles",
                      "--discovery", "server", "-k", "2", "--timeout", "100"], timeout=120)
    rc = ros.wait(proc, 130)
    text = ros.output(proc)
    assert rc == 0, text[-3000:]
    assert "converged: matching diameter < " in text, text[-2000:]
    server = re.search(r"discovery server:127\.0\.0\.1:(\d+)", text)
    assert server, text[:2000]
    assert _server_processes(int(server.group(1))) == []


# -- three namespace hosts -----------------------------------------------------------------------

@pytest.fixture
def net():
    yield from three_hosts()


@needs_ros
def test_twelve_agents_on_three_hosts_equal_the_centralised_run(net, tmp_path):
    out = tmp_path / "final.npz"
    _, texts, root, _ = run_on_hosts(net, tmp_path, lockstep_argvs(SCENE, 12, out))
    assert "4 of 12 agents (8-11)" in texts[2]
    check_lockstep_on_hosts(scene_path(SCENE), texts, out, 12)
    assert root.packets() == [], "DDS packets reached the root namespace"
    assert root.matched() == 0, "the root namespace's interfaces saw DDS packets"
