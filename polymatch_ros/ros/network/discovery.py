"""How the DDS participants of a run find each other: one spec string, the environments it needs.

    localhost               loopback only, simple discovery (the default; at most 32
                            participants per host and domain: rmw_fastrtps probes 32 ports)
    subnet                  simple discovery by multicast on every interface of the host
    server                  a Fast DDS discovery server on 127.0.0.1 and a free UDP port
    server:HOST:PORT        a discovery server listening on HOST:PORT (started here, or
                            elsewhere when HOST is another machine's address)
    peers:ADDR,ADDR,...     unicast discovery with the listed hosts only (ROS_STATIC_PEERS)

Three kinds of process take part.  *Clients* (agents, the monitor's own traffic) only learn of
the endpoints they match.  *Super clients* (whole-graph tools: the monitor, `polymatch echo`)
learn of every participant (``ROS_SUPER_CLIENT=TRUE``).  The *server* is a plain rclpy
participant whose default XML profile makes it a Fast DDS discovery server (``discoveryProtocol``
SERVER, GUID prefix ``44.53.<id>.5f.45.50.52.4f.53.49.4d.41``, a unicast metatraffic locator): see
``server_profile_xml`` and ``python -m polymatch_ros.ros.network.discovery_server``.
Domain ids do not
separate runs that share a server, so each run gets its own server port (``free_udp_port``).
Under a server there is no 32-participant limit: clients talk to the server, not to probed ports.
Clients of a server run with ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET (they still send discovery to
the server only) and over UDPv4 only (``SERVER_CLIENT_TRANSPORTS``); see the measurements at
``discovery_environments``.
"""

from __future__ import annotations

import dataclasses
import os
import socket
import subprocess
import sys
from collections.abc import Mapping, Sequence
from xml.etree import ElementTree

from ...core.errors import ParameterError
from .environment import NETWORK_PROFILE, PROFILE

KINDS: tuple[str, ...] = ("localhost", "subnet", "server", "peers")
DEFAULT_SERVER_HOST: str = "127.0.0.1"
FASTDDS_NAMESPACE: str = "http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles"
ROLES: tuple[str, ...] = ("client", "super_client", "server")
SERVER_CLIENT_TRANSPORTS: str = "UDPv4"
# Variables a discovery mode sets or clears; None in an overlay removes the variable.
DISCOVERY_VARIABLES: tuple[str, ...] = ("ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_STATIC_PEERS",
                       "ROS_DISCOVERY_SERVER", "ROS_SUPER_CLIENT")


#: what the discovery server prints once it listens (``discovery_server.serve``)
READY_LINE: str = "discovery server: listening on"
#: how long ``start_discovery_server`` waits for that line
SERVER_READY_SECONDS: float = 20.0


def server_guid_prefix(server_id: int = 0) -> str:
    """The GUID prefix ROS_DISCOVERY_SERVER assigns to the server at position ``server_id``."""
    if not 0 <= server_id <= 255:
        raise ParameterError(f"discovery server id {server_id} is not in 0..255")
    return f"44.53.{server_id:02x}.5f.45.50.52.4f.53.49.4d.41"


@dataclasses.dataclass(frozen=True)
class DiscoverySpec:
    """A parsed discovery spec; ``port`` 0 means "pick a free port when the run starts"."""

    kind: str
    host: str = ""
    port: int = 0
    peers: tuple[str, ...] = ()

    def __str__(self) -> str:
        if self.kind == "server":
            return f"server:{self.host}:{self.port}" if self.port else "server"
        if self.kind == "peers":
            return "peers:" + ",".join(self.peers)
        return self.kind


def _port(text: str, spec: str) -> int:
    if not text.isdigit() or not 1 <= int(text) <= 65535:
        raise ParameterError(f"discovery {spec!r}: port {text!r} is not a number in 1..65535")
    return int(text)


def _address(text: str, spec: str) -> str:
    allowed = set("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789.-_")
    if not text or not set(text) <= allowed or text.startswith(("-", ".")):
        raise ParameterError(f"discovery {spec!r}: {text!r} is not a host name or IPv4 address")
    return text


def parse_discovery_spec(text: str | None) -> DiscoverySpec:
    """``localhost | subnet | server[:HOST:PORT] | peers:ADDR,ADDR,...`` -> DiscoverySpec.

    Raises ParameterError (one line) for anything else.
    """
    spec = (text or "").strip()
    kind, _, rest = spec.partition(":")
    if kind not in KINDS:
        raise ParameterError(f"discovery {spec!r}: the kind must be one of {', '.join(KINDS)}"
                             " (e.g. server:127.0.0.1:11811 or peers:10.0.0.2,10.0.0.3)")
    if kind in ("localhost", "subnet"):
        if rest or spec != kind:
            raise ParameterError(f"discovery {spec!r}: {kind} takes no arguments")
        return DiscoverySpec(kind)
    if kind == "server":
        if spec == "server":
            return DiscoverySpec("server", DEFAULT_SERVER_HOST, 0)
        host, sep, port = rest.rpartition(":")
        if not sep:
            raise ParameterError(f"discovery {spec!r}: write server or server:HOST:PORT")
        return DiscoverySpec("server", _address(host, spec), _port(port, spec))
    peers = tuple(peer.strip() for peer in rest.split(","))
    if not rest or any(not peer for peer in peers):
        raise ParameterError(f"discovery {spec!r}: list the peers as peers:ADDR,ADDR,...")
    return DiscoverySpec("peers", peers=tuple(_address(peer, spec) for peer in peers))


def free_udp_port(host: str = DEFAULT_SERVER_HOST) -> int:
    """A UDP port on ``host`` that nothing is bound to right now (the kernel's pick)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind((host, 0))
        return int(sock.getsockname()[1])


def lease_seconds() -> float:
    """The participants' lease duration in the shipped profile (``leaseDuration``): how long a
    participant that vanished without a goodbye is still taken for present."""
    tree = ElementTree.parse(PROFILE)
    ns = f"{{{FASTDDS_NAMESPACE}}}"
    lease = tree.getroot().find(f".//{ns}discovery_config/{ns}leaseDuration")
    if lease is None:
        return 20.0  # Fast DDS's own default
    sec, nanosec = lease.find(f"{ns}sec"), lease.find(f"{ns}nanosec")
    return float(sec.text if sec is not None and sec.text else 0) + float(
        nanosec.text if nanosec is not None and nanosec.text else 0) * 1e-9


def _fast_discovery_settings() -> str:
    """The discovery_config children of the shipped profile (lease, announcements), as XML."""
    tree = ElementTree.parse(PROFILE)
    found = tree.getroot().find(f".//{{{FASTDDS_NAMESPACE}}}discovery_config")
    if found is None:
        return ""
    ElementTree.register_namespace("", FASTDDS_NAMESPACE)
    parts = [ElementTree.tostring(child, encoding="unicode") for child in found]
    return "".join(part.replace(f' xmlns="{FASTDDS_NAMESPACE}"', "") for part in parts)


def server_profile_xml(host: str, port: int, server_id: int = 0) -> str:
    """The default participant profile that makes an rclpy process a discovery server.

    Its metatraffic (discovery) and user traffic listen on ``host`` only, at ``port`` for
    discovery, with the shipped profile's lease and announcement settings.
    """
    locator = f"<locator><udpv4><address>{host}</address><port>{port}</port></udpv4></locator>"
    user_locator = f"<locator><udpv4><address>{host}</address></udpv4></locator>"
    return f"""<?xml version="1.0" encoding="UTF-8" ?>
<dds xmlns="{FASTDDS_NAMESPACE}">
  <profiles>
    <participant profile_name="polymatch_discovery_server" is_default_profile="true">
      <rtps>
        <prefix>{server_guid_prefix(server_id)}</prefix>
        <defaultUnicastLocatorList>{user_locator}</defaultUnicastLocatorList>
        <builtin>
          <discovery_config>
            <discoveryProtocol>SERVER</discoveryProtocol>
            {_fast_discovery_settings()}
          </discovery_config>
          <metatrafficUnicastLocatorList>{locator}</metatrafficUnicastLocatorList>
        </builtin>
      </rtps>
    </participant>
  </profiles>
</dds>
"""


@dataclasses.dataclass(frozen=True)
class DiscoveryEnvironments:
    """What each kind of process needs: environment overlays (None = remove the variable).

    ``server`` and ``server_profile`` (the written XML file) are set for a ``server`` spec
    only; ``spec`` has the port that was picked.
    """

    spec: DiscoverySpec
    client: dict[str, str | None]
    super_client: dict[str, str | None]
    server: dict[str, str | None] | None = None
    server_profile: str | None = None

    def for_role(self, role: str, base: Mapping[str, str] | None = None) -> dict[str, str]:
        """``base`` (default: this process's environment) with the overlay of ``role`` applied."""
        if role not in ROLES or getattr(self, role) is None:
            raise ParameterError(f"no {role} environment for discovery {self.spec}")
        return apply_environment(os.environ if base is None else base, getattr(self, role))


def apply_environment(base: Mapping[str, str],
                      overlay: Mapping[str, str | None]) -> dict[str, str]:
    """A copy of ``base`` with ``overlay`` applied (a value of None removes the variable)."""
    env = dict(base)
    for name, value in overlay.items():
        if value is None:
            env.pop(name, None)
        else:
            env[name] = value
    return env


def _overlay(**values: str) -> dict[str, str | None]:
    """Discovery across hosts takes the network profile: the shipped one plus reliable writers
    that heartbeat every 100 ms (repairs on a lossy link; see the file)."""
    overlay: dict[str, str | None] = dict.fromkeys(DISCOVERY_VARIABLES)
    overlay["FASTRTPS_DEFAULT_PROFILES_FILE"] = NETWORK_PROFILE
    overlay.update(values)
    return overlay


def discovery_environments(spec: str | DiscoverySpec, directory: str | None = None,
                           port: int | None = None) -> DiscoveryEnvironments:
    """The environments of a run's clients, super clients and (for ``server``) its server.

    ``spec`` is a spec string or DiscoverySpec.  For ``server`` without a port, ``port`` or a
    free one is used; the server's XML profile is written into ``directory`` (required then).
    """
    spec = spec if isinstance(spec, DiscoverySpec) else parse_discovery_spec(spec)
    if spec.kind == "localhost":
        client = _overlay(ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
                          FASTRTPS_DEFAULT_PROFILES_FILE=PROFILE)
        return DiscoveryEnvironments(spec, client, dict(client))
    if spec.kind == "subnet":
        client = _overlay(ROS_AUTOMATIC_DISCOVERY_RANGE="SUBNET")
        return DiscoveryEnvironments(spec, client, dict(client))
    if spec.kind == "peers":
        client = _overlay(ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
                          ROS_STATIC_PEERS=";".join(spec.peers))
        return DiscoveryEnvironments(spec, client, dict(client))
    if directory is None:
        raise ParameterError("discovery server: a directory for the server's profile is needed")
    spec = dataclasses.replace(spec, port=spec.port or port or free_udp_port(spec.host))
    profile = os.path.join(directory, f"discovery_server_{spec.port}.xml")
    with open(profile, "w") as out:
        out.write(server_profile_xml(spec.host, spec.port))
    address = f"{spec.host}:{spec.port}"
    # Clients under SUBNET: a client sends discovery only to the server (no multicast; measured
    # on a namespace bridge), and with LOCALHOST some matched writers' data never arrived
    # (40 clients on one host under load: 4 of 9 runs lost writers; 0 of 7 with SUBNET).
    # UDPv4 only: over shared memory a late reader matched all 40 writers yet got no data
    # from some of them (2 of 3 runs under load; 0 of 8 over UDPv4).
    client = _overlay(ROS_DISCOVERY_SERVER=address, ROS_AUTOMATIC_DISCOVERY_RANGE="SUBNET",
                      FASTDDS_BUILTIN_TRANSPORTS=SERVER_CLIENT_TRANSPORTS)
    super_client = dict(client, ROS_SUPER_CLIENT="TRUE")
    # A server under LOCALHOST cannot open its port (rmw adds a default unicast locator).  UDPv4
    # only, as its clients: with Fast DDS's built-in shared memory as well, a server made a
    # segment in /dev/shm, and shared-memory ports once clients had found it.
    server = _overlay(ROS_AUTOMATIC_DISCOVERY_RANGE="SUBNET",
                      FASTRTPS_DEFAULT_PROFILES_FILE=profile,
                      FASTDDS_BUILTIN_TRANSPORTS=SERVER_CLIENT_TRANSPORTS)
    return DiscoveryEnvironments(spec, client, super_client, server, profile)


class DiscoveryServer:
    """A ``python -m polymatch_ros.ros.network.discovery_server`` (bounded by ``timeout``),
    supervised like the run's other processes (``recovery.Process``): restarted on the same
    address, its clients find it again."""

    name = "discovery_server"
    hung_for: float | None = None  # never taken for hung: it only answers discovery
    argv: list[str]
    env: dict[str, str]
    host: str
    port: int
    log_path: str
    process: subprocess.Popen[bytes]

    @property
    def restart_delay(self) -> float:
        """A server restarted under its old GUID within its clients' lease is taken by them
        for the old one, still present: they never announce their endpoints to it again, and
        a participant that joins later meets nobody.  So it comes back once the lease ran out,
        when the clients have dropped it and ping its address again."""
        return lease_seconds() + 1.0

    def __init__(self, argv: Sequence[str], env: Mapping[str, str], host: str, port: int,
                 log_path: str) -> None:
        self.argv, self.env = list(argv), dict(env)
        self.host, self.port, self.log_path = host, port, log_path

    @property
    def address(self) -> str:
        return f"{self.host}:{self.port}"

    @property
    def pid(self) -> int:
        return self.process.pid

    def launch(self) -> None:
        """Start it and wait (at most ``SERVER_READY_SECONDS``) until it listens; raises
        PolymatchError if it does not."""
        import time

        from ...core.errors import PolymatchError

        with open(self.log_path, "w") as log:
            self.process = subprocess.Popen(self.argv, env=self.env, stdout=log,
                                            stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
        deadline = time.monotonic() + SERVER_READY_SECONDS
        while time.monotonic() < deadline and self.process.poll() is None:
            if READY_LINE in self.output():
                return
            time.sleep(0.05)
        self.stop()
        lines = self.output().strip().splitlines() or ["no output"]
        raise PolymatchError(f"discovery server on {self.address} did not start: {lines[-1]}")

    def restart(self) -> None:
        self.launch()

    def poll(self) -> int | None:
        return self.process.poll()

    def ended_well(self) -> bool:
        """It ran its time out (``timeout`` ended it) or was stopped: not a death."""
        return self.process.poll() in (0, 124)

    def tail(self, n: int = 5) -> list[str]:
        return self.output().strip().splitlines()[-n:]

    def output(self) -> str:
        with open(self.log_path) as log:
            return log.read()

    def stop(self, grace: float = 5.0) -> int | None:
        """SIGINT by PID, SIGKILL after ``grace`` seconds; returns the exit code."""
        if self.process.poll() is None:
            self.process.send_signal(2)
            try:
                self.process.wait(timeout=grace)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait(timeout=grace)
        return self.process.returncode


def start_discovery_server(port: int, host: str = DEFAULT_SERVER_HOST, seconds: float = 600.0,
                           env: Mapping[str, str] | None = None, log_path: str | None = None,
                           prefix: Sequence[str] = ()) -> DiscoveryServer:
    """Start a discovery server on host:port and wait (at most ``SERVER_READY_SECONDS``) until it
    listens.  It ends by itself after ``seconds`` (``timeout -k 5``); ``prefix`` is put before
    the command (e.g. ``("ip", "netns", "exec", NAME)``).  Raises PolymatchError if it fails.
    """
    if log_path is None:
        import tempfile
        log_path = tempfile.mkstemp(prefix=f"polymatch_ds_{port}_", suffix=".log")[1]
    argv = list(prefix) + ["timeout", "-k", "5", str(seconds), sys.executable, "-m",
                           "polymatch_ros.ros.network.discovery_server", "--host", host,
                           "--port", str(port), "--seconds", str(seconds)]
    server = DiscoveryServer(argv, os.environ if env is None else env, host, port, log_path)
    server.launch()
    return server
