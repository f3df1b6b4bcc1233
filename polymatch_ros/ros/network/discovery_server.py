"""A Fast DDS discovery server as a small rclpy process.

    python -m polymatch_ros.ros.network.discovery_server --port 11811 [--host 127.0.0.1]
        [--id 0] [--seconds 3600]

The Fast DDS wheel's own ``fast-discovery-server`` does not start as installed, but any
participant whose default XML profile sets ``discoveryProtocol`` SERVER is a server: this process
writes that profile (``discovery.server_profile_xml``), points FASTRTPS_DEFAULT_PROFILES_FILE at
it and creates one node.  Clients reach it with ``ROS_DISCOVERY_SERVER=HOST:PORT`` (the server
at position ``--id`` of that list).  It prints ``discovery server: listening on HOST:PORT`` once
the port is open, and runs until SIGINT/SIGTERM or ``--seconds``.  Bad arguments, or a port it
cannot open: one line ``polymatch: error: ...`` and exit 2.
"""

from __future__ import annotations

import argparse
import errno
import os
import signal
import socket
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NoReturn

from ...core.errors import ParameterError, PolymatchError
from ..process.teardown import end_process, teardown_watchdog
from . import discovery
from .discovery import READY_LINE


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:
        raise ParameterError(message)


@dataclass(frozen=True)
class ServerOptions:
    """Where the server listens, its position in ROS_DISCOVERY_SERVER, how long it runs."""

    host: str
    port: int
    server_id: int
    seconds: float


def parse(argv: Sequence[str]) -> tuple[ServerOptions, discovery.DiscoverySpec]:
    """The checked options and their server spec; ParameterError (one line) otherwise."""
    parser = _Parser(prog="python -m polymatch_ros.ros.network.discovery_server")
    parser.add_argument("--port", type=int, required=True)
    parser.add_argument("--host", default=discovery.DEFAULT_SERVER_HOST)
    parser.add_argument("--id", type=int, default=0, dest="server_id")
    parser.add_argument("--seconds", type=float, default=3600.0)
    args = parser.parse_args(argv)
    spec = discovery.parse_discovery_spec(f"server:{args.host}:{args.port}")
    discovery.server_guid_prefix(args.server_id)
    if args.seconds <= 0:
        raise ParameterError(f"--seconds {args.seconds} must be positive")
    return ServerOptions(args.host, args.port, args.server_id, args.seconds), spec


def port_taken(host: str, port: int) -> bool:
    """True when a UDP socket is bound to host:port (binding it ourselves fails)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        try:
            sock.bind((host, port))
        except OSError as exc:
            return exc.errno == errno.EADDRINUSE
        return False


def serve(args: ServerOptions) -> None:
    """Become the server participant; return once stopped.

    The profile file lives only until the participant has read it: a server ended by SIGKILL
    (the fault tests kill it) or by the teardown watchdog leaves nothing behind in the
    temporary directory.
    """
    if port_taken(args.host, args.port):
        raise ParameterError(f"UDP port {args.host}:{args.port} is already in use")
    handle, profile = tempfile.mkstemp(prefix="polymatch_ds_", suffix=".xml")
    with os.fdopen(handle, "w") as out:
        out.write(discovery.server_profile_xml(args.host, args.port, args.server_id))
    for name in discovery.DISCOVERY_VARIABLES:
        os.environ.pop(name, None)
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "SUBNET"   # LOCALHOST breaks the server port
    os.environ["FASTRTPS_DEFAULT_PROFILES_FILE"] = profile
    stop: list[int] = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    signal.signal(signal.SIGINT, lambda *_: stop.append(1))
    import rclpy
    from rclpy.node import Node
    rclpy.init(signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    try:
        node = Node("polymatch_discovery_server")   # the participant reads the profile here
    finally:
        os.unlink(profile)
    if not port_taken(args.host, args.port):
        raise ParameterError(f"the discovery server did not open UDP {args.host}:{args.port}")
    print(f"{READY_LINE} {args.host}:{args.port} (GUID prefix "
          f"{discovery.server_guid_prefix(args.server_id)})", flush=True)
    end = time.monotonic() + args.seconds
    while not stop and time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.2)
    with teardown_watchdog(exit_code=0):
        node.destroy_node()
        rclpy.try_shutdown()


def main(argv: Sequence[str] | None = None) -> int:
    """The server process: 0 once stopped, the error's exit code after one line."""
    try:
        args, _ = parse(sys.argv[1:] if argv is None else argv)
        serve(args)
    except PolymatchError as exc:
        print(f"polymatch: error: {exc}", file=sys.stderr)
        return exc.exit_code
    return 0


if __name__ == "__main__":
    end_process(main())
