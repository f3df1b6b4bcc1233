"""Discovery modes: the spec parser, the environments per role, and a discovery server that
carries more participants than loopback simple discovery reaches (rmw_fastrtps probes 32 ports).

Everything here stays on 127.0.0.1.  The server test starts 40 publisher processes (40
participants), then two listeners (a super client and a plain client) after all of them: a late
listener under LOCALHOST simple discovery only finds the participants on the first 32 ports.
"""

import contextlib
import os
import shutil
import subprocess
import sys
import time
from xml.etree import ElementTree

import pytest
from netns_hosts import Capture, root_interfaces
from proc_group import Processes
from ros_harness import needs_ros

from polymatch_ros.core.errors import ParameterError, PolymatchError
from polymatch_ros.ros.supervisor import discovery
from polymatch_ros.ros.supervisor.discovery import DiscoverySpec, parse_discovery_spec

# 34 publishers and 2 listeners: more participants than LOCALHOST discovery reaches (32)
PUBLISHERS = 34


# -- the spec parser ------------------------------------------------------------------------

@pytest.mark.parametrize("text, expected", [
    ("localhost", DiscoverySpec("localhost")),
    ("subnet", DiscoverySpec("subnet")),
    ("server", DiscoverySpec("server", "127.0.0.1", 0)),
    ("server:127.0.0.1:11811", DiscoverySpec("server", "127.0.0.1", 11811)),
    ("server:10.213.0.1:7000", DiscoverySpec("server", "10.213.0.1", 7000)),
    ("server:robot-base.local:65535", DiscoverySpec("server", "robot-base.local", 65535)),
    ("peers:10.213.0.2", DiscoverySpec("peers", peers=("10.213.0.2",))),
    ("peers:10.213.0.2,10.213.0.3, host-c", DiscoverySpec(
        "peers", peers=("10.213.0.2", "10.213.0.3", "host-c"))),
    ("  server  ", DiscoverySpec("server", "127.0.0.1", 0)),
])
def test_spec_parses(text, expected):
    assert parse_discovery_spec(text) == expected


@pytest.mark.parametrize("text, words", [
    ("", "kind must be one of"),
    ("multicast", "kind must be one of"),
    ("LOCALHOST", "kind must be one of"),
    ("localhost:1", "takes no arguments"),
    ("subnet:", "takes no arguments"),
    ("server:", "server:HOST:PORT"),
    ("server:11811", "server:HOST:PORT"),
    ("server:127.0.0.1:", "port ''"),
    ("server:127.0.0.1:0", "1..65535"),
    ("server:127.0.0.1:65536", "1..65535"),
    ("server:127.0.0.1:-5", "1..65535"),
    ("server:127.0.0.1:http", "1..65535"),
    ("server::11811", "host name"),
    ("server:a b:11811", "host name"),
    ("peers:", "peers:ADDR,ADDR"),
    ("peers", "peers:ADDR,ADDR"),
    ("peers:10.0.0.1,,10.0.0.2", "peers:ADDR,ADDR"),
    ("peers:10.0.0.1;10.0.0.2", "host name"),
])
def test_malformed_spec_is_one_line_parameter_error(text, words):
    with pytest.raises(ParameterError) as caught:
        parse_discovery_spec(text)
    message = str(caught.value)
    assert words in message and "\n" not in message
    assert isinstance(caught.value, PolymatchError) and caught.value.exit_code == 2


def test_spec_round_trips_through_str():
    for text in ("localhost", "subnet", "server", "server:10.0.0.1:7000", "peers:a,b"):
        assert str(parse_discovery_spec(text)) == text


# -- environments per role -------------------------------------------------------------------

def test_localhost_is_the_default_and_stays_on_loopback():
    envs = discovery.discovery_environments("localhost")
    base = {"ROS_DISCOVERY_SERVER": "10.0.0.9:1", "ROS_STATIC_PEERS": "10.0.0.8", "KEEP": "1"}
    for role in ("client", "super_client"):
        env = envs.for_role(role, base)
        assert env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
        assert "ROS_DISCOVERY_SERVER" not in env and "ROS_STATIC_PEERS" not in env
        assert env["KEEP"] == "1"
        assert env["FASTRTPS_DEFAULT_PROFILES_FILE"].endswith("fastdds_profile.xml")
    assert envs.server is None
    with pytest.raises(ParameterError):
        envs.for_role("server", base)


def test_subnet_and_peers_environments():
    subnet = discovery.discovery_environments("subnet").for_role("client", {})
    assert subnet["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "SUBNET"
    assert "ROS_STATIC_PEERS" not in subnet
    peers = discovery.discovery_environments("peers:10.213.0.2,10.213.0.3")
    env = peers.for_role("super_client", {"ROS_SUPER_CLIENT": "TRUE"})
    assert env["ROS_STATIC_PEERS"] == "10.213.0.2;10.213.0.3"
    assert env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    assert "ROS_SUPER_CLIENT" not in env


def test_server_environments_and_profile(tmp_path):
    envs = discovery.discovery_environments("server", str(tmp_path))
    port = envs.spec.port
    assert envs.spec.host == "127.0.0.1" and 0 < port < 65536
    client = envs.for_role("client", {"ROS_SUPER_CLIENT": "TRUE"})
    assert client["ROS_DISCOVERY_SERVER"] == f"127.0.0.1:{port}"
    assert client["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "SUBNET"
    assert client["FASTDDS_BUILTIN_TRANSPORTS"] == "UDPv4"
    assert "ROS_SUPER_CLIENT" not in client
    assert envs.for_role("super_client", {})["ROS_SUPER_CLIENT"] == "TRUE"
    server = envs.for_role("server", {"ROS_DISCOVERY_SERVER": "x", "ROS_STATIC_PEERS": "y"})
    assert server["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "SUBNET"
    assert "ROS_DISCOVERY_SERVER" not in server and "ROS_STATIC_PEERS" not in server
    assert server["FASTRTPS_DEFAULT_PROFILES_FILE"] == envs.server_profile
    ns = {"f": discovery.FASTDDS_NAMESPACE}
    rtps = ElementTree.parse(envs.server_profile).getroot().find(".//f:participant/f:rtps", ns)
    assert rtps.findtext("f:prefix", namespaces=ns) == "44.53.00.5f.45.50.52.4f.53.49.4d.41"
    builtin = rtps.find("f:builtin", ns)
    assert builtin.findtext("f:discovery_config/f:discoveryProtocol", namespaces=ns) == "SERVER"
    assert builtin.findtext("f:discovery_config/f:leaseAnnouncement/f:sec", namespaces=ns) == "1"
    locator = builtin.find("f:metatrafficUnicastLocatorList/f:locator/f:udpv4", ns)
    assert locator.findtext("f:address", namespaces=ns) == "127.0.0.1"
    assert locator.findtext("f:port", namespaces=ns) == str(port)


def test_remote_server_clients_use_the_subnet(tmp_path):
    envs = discovery.discovery_environments("server:10.213.0.1:7000", str(tmp_path))
    env = envs.for_role("client", {})
    assert env["ROS_DISCOVERY_SERVER"] == "10.213.0.1:7000"
    assert env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "SUBNET"


def test_server_needs_a_directory_and_ids_are_bounded():
    with pytest.raises(ParameterError):
        discovery.discovery_environments("server")
    assert discovery.server_guid_prefix(2).startswith("44.53.02.5f")
    with pytest.raises(ParameterError):
        discovery.server_guid_prefix(256)


def test_free_udp_port_is_free():
    import socket
    port = discovery.free_udp_port()
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", port))


@pytest.mark.parametrize("argv, words", [
    (["--port", "0"], "1..65535"),
    (["--port", "nine"], "invalid int"),
    ([], "--port"),
    (["--port", "7000", "--host", "a b"], "host name"),
    (["--port", "7000", "--seconds", "0"], "positive"),
    (["--port", "7000", "--id", "300"], "0..255"),
])
def test_server_command_rejects_bad_arguments(argv, words):
    server = "polymatch_ros.ros.supervisor.discovery_server"
    out = subprocess.run([sys.executable, "-m", server] + argv, check=False,
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 2
    assert out.stderr.startswith("polymatch: error: ") and words in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1 and "Traceback" not in out.stderr


# -- more than 32 participants through a discovery server --------------------------------------

def root_capture(tmp_path, interfaces=None, label="root"):
    """tcpdump for DDS on the machine's non-loopback interfaces, where root and tcpdump allow."""
    if os.geteuid() != 0 or shutil.which("tcpdump") is None:
        return contextlib.nullcontext()
    return Capture(str(tmp_path), interfaces or root_interfaces(), label=label)


@needs_ros
def test_server_carries_more_participants_than_localhost_discovery_reaches(tmp_path):
    from domain_coordinator import domain_id
    started = time.monotonic()
    procs = Processes(str(tmp_path))
    envs = discovery.discovery_environments("server", str(tmp_path))
    server = None
    with domain_id() as domain, root_capture(tmp_path) as capture, \
            root_capture(tmp_path, ["lo"], "loopback") as loopback:
        base = dict(os.environ, ROS_DOMAIN_ID=str(domain), PYTHONUNBUFFERED="1")
        try:
            server = discovery.start_discovery_server(
                envs.spec.port, env=envs.for_role("server", base), seconds=120,
                log_path=str(tmp_path / "server.log"))
            client = envs.for_role("client", base)
            publishers = [procs.probe(f"p{i}", client, 90) for i in range(PUBLISHERS)]
            assert procs.wait_for(publishers, "ready", 60) == []
            names = [f"p{i}/0" for i in range(PUBLISHERS)]
            listeners = [procs.probe("super", envs.for_role("super_client", base), 60,
                                     listen=True, expect=names),
                         procs.probe("client", client, 60, listen=True, expect=names)]
            late = procs.wait_for(listeners, "done", 45)
            assert late == [], "\n".join(procs.output(proc)[-600:] for proc in late)
            for listener in listeners:
                heard = [line for line in procs.output(listener).splitlines()
                         if line.startswith("heard: ")]
                assert heard == ["heard: " + ",".join(sorted(names))]
            assert all(proc.poll() is None for proc in publishers)
        finally:
            procs.close()
            if server is not None:
                assert server.stop() == 0, server.output()
    if capture is not None:
        assert capture.packets() == [], "DDS packets left the machine"
        assert capture.matched() == 0, "DDS packets left the machine"
        # even between processes of this machine, no packet is addressed to eth0's address
        assert loopback.matched() > 100
        assert {address.split(".")[0] for address in loopback.addresses()} == {"127"}
    print(f"\n{PUBLISHERS} participants via a discovery server: "
          f"{time.monotonic() - started:.1f} s")


@needs_ros
def test_server_start_fails_cleanly_on_a_taken_port(tmp_path):
    import socket
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as holder:
        holder.bind(("127.0.0.1", 0))
        port = holder.getsockname()[1]
        with pytest.raises(PolymatchError, match="already in use"):
            discovery.start_discovery_server(port, seconds=30,
                                             log_path=str(tmp_path / "server.log"))


@needs_ros
def test_a_listening_server_keeps_no_file_a_kill_could_leave_behind(tmp_path):
    """The server's XML profile is removed once its participant has read it: a server ended by
    SIGKILL (as the fault tests end it) leaves nothing in the temporary directory."""
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    port = discovery.free_udp_port()
    server = discovery.start_discovery_server(
        port, seconds=60, env=dict(os.environ, TMPDIR=str(scratch)),
        log_path=str(tmp_path / "server.log"))
    try:
        assert server.process.poll() is None, server.output()
        assert list(scratch.iterdir()) == []
    finally:
        assert server.stop() == 0, server.output()
    assert list(scratch.iterdir()) == []
