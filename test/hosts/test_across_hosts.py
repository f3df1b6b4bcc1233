"""`polymatch run` across hosts: --only, --no-monitor, --discovery.

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
import subprocess
import sys

import pytest
from host_runs import check_lockstep_on_hosts, run_on_hosts, three_hosts
from ros_harness import needs_ros, scene_path

from benchmarks.hosts.runs import (
    lockstep_argvs,
)
from polymatch_ros.core.errors import ParameterError
from polymatch_ros.ros.supervisor.children import describe_agents, parse_only

SCENE = "mixed_triangles_tetrahedra"        # 12 agents (6 triangles, 6 tetrahedra)


# -- --only --------------------------------------------------------------------------------------

@pytest.mark.parametrize("text,n,expected", [
    ("0-7,12", 16, [0, 1, 2, 3, 4, 5, 6, 7, 12]),
    (" 3 ", 4, [3]),
    ("0-3,2-5", 8, [0, 1, 2, 3, 4, 5]),
    ("11, 0 - 1", 12, [0, 1, 11]),
    ("5-5", 6, [5]),
])
def test_only_names_agents(text, n, expected):
    assert parse_only(text, n) == expected
    assert parse_only(describe_agents(expected), n) == expected


@pytest.mark.parametrize("text,words", [
    ("", "e.g. --only 0-7,12"), ("a", "e.g."), ("1-", "e.g."), ("-1", "e.g."),
    ("0,,2", "e.g."), ("0-2-4", "e.g."), ("\u0663", "e.g."), ("1.5", "e.g."),
    ("3-1", "runs backwards"), ("0-12", "agent 12 is not in 0..11"), ("99", "not in 0..11"),
])
def test_malformed_or_out_of_range_only_is_one_line(text, words):
    with pytest.raises(ParameterError) as raised:
        parse_only(text, 12)
    assert words in str(raised.value) and "\n" not in str(raised.value)


def test_describe_agents():
    assert describe_agents([0, 1, 2, 3, 12]) == "0-3,12"
    assert describe_agents([4]) == "4"
    assert describe_agents([]) == ""


def _cli(*argv, env=None):
    return subprocess.run([sys.executable, "-m", "polymatch_ros.cli", "run"] + list(argv),
                          capture_output=True, text=True, timeout=60, env=env,
                          stdin=subprocess.DEVNULL)


@pytest.mark.parametrize("argv,words", [
    (["--only", "0-8"], "agent 8 is not in 0..7"),
    (["--only", "x"], "--only 'x'"),
    (["--only", "0-3"], "set the same ROS_DOMAIN_ID on every host"),
    (["--discovery", "multicast"], "the kind must be one of"),
    (["--discovery", "server:127.0.0.1:0"], "port '0'"),
])
def test_bad_host_options_exit_2_with_one_line(argv, words):
    env = {k: v for k, v in os.environ.items() if k != "ROS_DOMAIN_ID"}
    out = _cli("congruent_triangles", *argv, env=env)
    assert out.returncode == 2, out.stderr
    assert out.stderr.startswith("polymatch: error: ") and words in out.stderr, out.stderr
    assert len(out.stderr.strip().splitlines()) == 1 and "Traceback" not in out.stderr


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
        if b"polymatch_ros.ros.supervisor.discovery_server" in argv and str(port).encode() in argv:
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
