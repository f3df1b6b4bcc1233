"""A discovery server carries more participants than loopback simple discovery reaches
(rmw_fastrtps probes 32 ports).

Everything here stays on 127.0.0.1.  The server test starts 34 publishing participants (two
processes of 17 contexts each), then two listeners (a super client and a plain client) after all
of them: a late listener under LOCALHOST simple discovery only finds the participants on the
first 32 ports.
"""

import contextlib
import os
import shutil
import time

import pytest
from netns_hosts import Capture, root_interfaces
from proc_group import Processes
from ros_harness import needs_ros

from polymatch_ros.core.errors import PolymatchError
from polymatch_ros.ros.network import discovery

# 34 publishers and 2 listeners: more participants than LOCALHOST discovery reaches (32); the
# publishers in two processes, since what counts is participants, and a process costs a start
PUBLISHER_PROCESSES, PARTICIPANTS_EACH = 2, 17
PUBLISHERS = PUBLISHER_PROCESSES * PARTICIPANTS_EACH


# -- more than 32 participants through a discovery server --------------------------------------

def root_capture(tmp_path, interfaces=None, label="root"):
    """tcpdump for DDS on the machine's non-loopback interfaces, where root and tcpdump allow."""
    if os.geteuid() != 0 or shutil.which("tcpdump") is None:
        return contextlib.nullcontext()
    return Capture(str(tmp_path), interfaces or root_interfaces(), label=label)


@needs_ros
def test_server_carries_more_participants_than_localhost_discovery_reaches(ros, tmp_path):
    started = time.monotonic()
    procs = Processes(str(tmp_path))
    envs = discovery.discovery_environments("server", str(tmp_path))
    server = None
    with root_capture(tmp_path) as capture, \
            root_capture(tmp_path, ["lo"], "loopback") as loopback:
        base = dict(ros.env, PYTHONUNBUFFERED="1")
        try:
            server = discovery.start_discovery_server(
                envs.spec.port, env=envs.for_role("server", base), seconds=120,
                log_path=str(tmp_path / "server.log"))
            client = envs.for_role("client", base)
            publishers = [procs.probe(f"p{i}", client, 90, participants=PARTICIPANTS_EACH)
                          for i in range(PUBLISHER_PROCESSES)]
            assert procs.wait_for(publishers, "ready", 60) == []
            names = [f"p{i}.{j}/0" for i in range(PUBLISHER_PROCESSES)
                     for j in range(PARTICIPANTS_EACH)]
            assert len(set(names)) == PUBLISHERS
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
def test_server_start_fails_cleanly_on_a_taken_port(ros, tmp_path):
    import socket
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as holder:
        holder.bind(("127.0.0.1", 0))
        port = holder.getsockname()[1]
        with pytest.raises(PolymatchError, match="already in use"):
            discovery.start_discovery_server(port, seconds=30, env=ros.env,
                                             log_path=str(tmp_path / "server.log"))


@needs_ros
def test_a_listening_server_keeps_no_file_a_kill_could_leave_behind(ros, tmp_path):
    """The server's XML profile is removed once its participant has read it: a server ended by
    SIGKILL (as the fault tests end it) leaves nothing in the temporary directory."""
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    port = discovery.free_udp_port()
    server = discovery.start_discovery_server(
        port, seconds=60, env=dict(ros.env, TMPDIR=str(scratch)),
        log_path=str(tmp_path / "server.log"))
    try:
        assert server.process.poll() is None, server.output()
        assert list(scratch.iterdir()) == []
    finally:
        assert server.stop() == 0, server.output()
    assert list(scratch.iterdir()) == []
