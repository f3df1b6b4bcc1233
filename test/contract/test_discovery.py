"""Discovery modes: the spec parser, the environments per role and the server command's
arguments (the server itself, carrying more participants than loopback simple discovery reaches:
test/ros/test_discovery_server.py)."""

import os
import subprocess
import sys
from xml.etree import ElementTree

import pytest

from polymatch_ros.core.errors import ParameterError, PolymatchError
from polymatch_ros.ros.network import discovery
from polymatch_ros.ros.network.discovery import DiscoverySpec, parse_discovery_spec

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
    assert server["FASTDDS_BUILTIN_TRANSPORTS"] == "UDPv4"  # no shared memory, as its clients
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
    server = "polymatch_ros.ros.network.discovery_server"
    out = subprocess.run([sys.executable, "-m", server] + argv, check=False,
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 2
    assert out.stderr.startswith("polymatch: error: ") and words in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1 and "Traceback" not in out.stderr


def _threads_after_numpy(env):
    """The threads of a Python process once it has imported numpy, as the kernel counts them."""
    code = ("import numpy\n"
            "print([ln.split()[1] for ln in open('/proc/self/status')\n"
            "       if ln.startswith('Threads')][0])")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         timeout=60, check=True)
    return int(out.stdout)


def test_node_processes_start_one_openblas_thread_unless_the_user_says_otherwise():
    """Every process a run starts steps in one thread: OpenBLAS starts no workers of its own
    there (one a core otherwise), and a user's OPENBLAS_NUM_THREADS wins."""
    from polymatch_ros.ros.network.environment import ros_environment

    base = {k: v for k, v in os.environ.items() if not k.startswith("OPENBLAS")}
    assert _threads_after_numpy(ros_environment(7, base=base)) == 1
    assert _threads_after_numpy(dict(ros_environment(7, base=base),
                                     OPENBLAS_NUM_THREADS="2")) == 2
    assert ros_environment(7, base=dict(base, OPENBLAS_NUM_THREADS="3"))[
        "OPENBLAS_NUM_THREADS"] == "3"


def test_a_reserved_domain_is_marked_for_the_run_and_only_that_domain(monkeypatch):
    """A test's or benchmark's environment names the domain it reserved; a run there has no
    other ensemble to look for, a run in any other domain (the user's) still looks."""
    from polymatch_ros.ros.network.environment import (
        RESERVED_DOMAIN,
        domain_reserved,
        private_ros_environment,
        ros_environment,
    )

    monkeypatch.setenv(RESERVED_DOMAIN, "12")  # a caller's own mark does not carry over
    env = private_ros_environment(42)
    assert env["ROS_DOMAIN_ID"] == "42" and env[RESERVED_DOMAIN] == "42"
    assert domain_reserved(42, env) and not domain_reserved(41, env)
    assert not domain_reserved(42, {}) and not domain_reserved(42, {RESERVED_DOMAIN: ""})
    user = {k: v for k, v in os.environ.items() if k != RESERVED_DOMAIN}
    assert RESERVED_DOMAIN not in ros_environment(42, base=user)
