"""Three hosts on one machine (network namespaces, see netns_hosts.py) running DDS across them.

Each host runs one rclpy process that publishes and listens; every one must hear all three.
Discovery across the hosts' subnet is tried three ways (multicast SUBNET, unicast static peers,
a discovery server in host 0).  Data goes over UDPv4 only (shared memory would bypass the
network between namespaces).  tcpdump on the root namespace's non-loopback interfaces must see
no DDS packet, while the same capture on the hosts' bridge must see plenty (the control that
the capture works).  The lossy variant drops 10% of what host 1 receives (nftables) and checks
that RELIABLE delivery still brings every message, in order.
"""

import os
import time

import pytest
from netns_hosts import Capture, provided_hosts, root_interfaces, unavailable_reason
from proc_group import Processes
from ros_harness import needs_ros

from polymatch_ros.ros.network import discovery

HOSTS = 3
SERVER_PORT = 11811          # inside host 0's own namespace: no other run can hold it


def hosts_or_skip(tools=()):
    reason = unavailable_reason(tools)
    if reason:
        pytest.skip(reason)


@pytest.fixture
def net():
    root_before = root_interfaces()
    yield from provided_hosts(HOSTS)
    assert root_interfaces() == root_before


def test_hosts_reach_each_other_and_nothing_else(net):
    for index, address in enumerate(net.addresses):
        shown = net.run(index, ["ip", "-4", "-o", "addr", "show", "dev", "eth0"]).stdout
        assert f"inet {address}/24" in shown
        assert net.run(index, ["ip", "link", "show", "lo"]).stdout.count("UP") >= 1
        routes = net.run(index, ["ip", "-4", "route"]).stdout
        assert "default" not in routes
    assert net.udp_delivered(0, 1) == 50
    assert net.udp_delivered(2, 0) == 50
    net.link_down(2)
    assert net.udp_delivered(0, 2, seconds=1.5) == 0
    net.link_up(2)
    deadline = time.monotonic() + 10
    while net.udp_delivered(0, 2, count=5, seconds=1.0) == 0 and time.monotonic() < deadline:
        pass
    assert net.udp_delivered(0, 2) == 50


def test_loss_rule_drops_about_a_tenth(net):
    hosts_or_skip(("nft",))
    net.add_loss(1, percent=10)
    delivered = net.udp_delivered(0, 1, count=400)
    assert 300 <= delivered <= 395          # binomial(400, 0.9): mean 360, sd 6
    assert net.dropped(1) == 400 - delivered
    assert net.udp_delivered(1, 0, count=100) == 100     # only what host 1 receives is dropped
    net.remove_loss(1)
    assert net.udp_delivered(0, 1, count=100) == 100


def discovery_environment(net, spec, base, tmp_path):
    """The client environment of ``spec`` in the hosts; starts the server in host 0."""
    if spec == "subnet":
        return discovery.discovery_environments("subnet").for_role("client", base), None
    if spec == "peers":
        peers = "peers:" + ",".join(net.addresses)
        return discovery.discovery_environments(peers).for_role("client", base), None
    envs = discovery.discovery_environments(f"server:{net.addresses[0]}:{SERVER_PORT}",
                                            str(tmp_path))
    server = discovery.start_discovery_server(
        SERVER_PORT, net.addresses[0], seconds=120, env=envs.for_role("server", base),
        log_path=str(tmp_path / "server.log"), prefix=net.prefix(0))
    return envs.for_role("client", base), server


def run_across_hosts(net, tmp_path, spec, messages=0, loss=0):
    """One probe per host; returns (the lines each printed, root packets, bridge packets)."""
    hosts_or_skip(("tcpdump",) + (("nft",) if loss else ()))
    from domain_coordinator import domain_id
    procs, server = Processes(str(tmp_path)), None
    names = [f"h{i}/0" for i in range(HOSTS)]
    with domain_id() as domain, Capture(str(tmp_path), root_interfaces()) as root, \
            Capture(str(tmp_path), ["br0"], net.bridge, "bridge") as bridge:
        base = dict(os.environ, ROS_DOMAIN_ID=str(domain), PYTHONUNBUFFERED="1",
                    FASTDDS_BUILTIN_TRANSPORTS="UDPv4")
        try:
            env, server = discovery_environment(net, spec, base, tmp_path)
            if loss:
                net.add_loss(1, percent=loss)
            probes = [procs.probe(f"h{i}", env, 60, prefix=net.prefix(i), expect=names,
                                  messages=messages) for i in range(HOSTS)]
            late = procs.wait_for(probes, "done", 50)
            outputs = {proc.name: procs.output(proc) for proc in probes}
            assert late == [], "\n".join(outputs[proc.name][-800:] for proc in late)
            dropped = net.dropped(1) if loss else 0
        finally:
            procs.close()
            if server is not None:
                server.stop()
    assert root.matched() == 0, "the root namespace's interfaces saw DDS packets"
    return outputs, root.packets(), bridge.packets(), dropped


@needs_ros
@pytest.mark.parametrize("spec", ["subnet", "peers", "server"])
def test_three_hosts_hear_each_other(net, tmp_path, spec):
    started = time.monotonic()
    outputs, root_packets, bridge_packets, _ = run_across_hosts(net, tmp_path, spec)
    for name, text in outputs.items():
        assert "heard: h0/0,h1/0,h2/0" in text.splitlines(), (name, text[-800:])
    assert root_packets == []
    assert len(bridge_packets) > 20
    print(f"\n3 hosts, discovery {spec}: {time.monotonic() - started:.1f} s")


@needs_ros
def test_reliable_delivery_survives_ten_percent_loss(net, tmp_path):
    started = time.monotonic()
    outputs, root_packets, bridge_packets, dropped = run_across_hosts(
        net, tmp_path, "peers", messages=100, loss=10)
    for name, text in outputs.items():
        lines = text.splitlines()
        assert "heard: h0/0,h1/0,h2/0" in lines, (name, text[-800:])
        assert not [line for line in lines if line.startswith("error:")]
    assert dropped > 10, "the loss rule dropped (almost) nothing"
    assert root_packets == []
    assert len(bridge_packets) > 100
    print(f"\n3 hosts, 10% loss into h1, {dropped} packets dropped, 3x100 messages delivered: "
          f"{time.monotonic() - started:.1f} s")
