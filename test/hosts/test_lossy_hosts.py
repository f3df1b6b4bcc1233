"""`polymatch run` across three namespace hosts when the network misbehaves.

* lockstep with 10% of what host 1 receives dropped (nftables): RELIABLE retransmission
  repairs every stage message, so the result still equals the centralised run to 1e-9;
* realtime with the same loss and 50 ms of injected delay (``--delay``): it still converges to
  the scene's tolerance (Theorem 4.2: the latest poses, delayed and some lost, suffice);
* realtime with host 0's link down for 5 s: the monitor on host 2 reports only the agents of
  hosts 1 and 2 while it is down, then every agent is heard again and the ensemble matches.

The monitor's reports are read as data: `polymatch echo` of its ``status`` topic inside host 2
prints each run record (``--json``), read with ``wire.echoed_run_records``.  In every test
tcpdump on the root namespace must match no DDS packet (the kernel's count).
"""

import sys
import time

import host_runs as hr
import pytest
from ros_harness import needs_ros

from benchmarks.hosts.runs import lockstep_argvs, scene_with
from polymatch_ros.core.scenes.scene import load_scene
from polymatch_ros.ros.network import discovery
from polymatch_ros.ros.wire import run_records

pytestmark = needs_ros

LOCKSTEP_SCENE = "mixed_triangles_tetrahedra"   # (F-2) triangles and tetrahedra, 12 of each
LOCKSTEP_AGENTS = 24                            # 8/8/8 over the hosts
LOSS = 10                     # percent of what host 1 receives
LOSSY_HOST = 1
DOWN_HOST, DOWN_SECONDS = 0, 5.0


@pytest.fixture
def net():
    yield from hr.three_hosts(("tcpdump", "nft"))


def lossy(net, index):
    """``during`` for run_on_hosts: drop LOSS% of what host ``index`` receives from the start;
    returns how many packets the rule dropped, read once every host's runner has ended."""
    net.add_loss(index, percent=LOSS)

    def count(procs, started, env):
        for proc in started:
            proc.wait(timeout=200)
        return net.dropped(index)

    return count


def _check_converged(scene_file, started, out):
    lead = started[2]
    assert lead.returncode == 0, f"the lead host's run did not converge (exit {lead.returncode})"
    tolerance = load_scene(scene_file).tolerance
    diameter = hr.saved_diameter(scene_file, out)
    assert diameter < tolerance, f"final matching diameter {diameter:.3e} >= {tolerance:g}"


def test_lockstep_under_ten_percent_loss_equals_the_centralised_run(net, tmp_path):
    started = time.monotonic()
    out = tmp_path / "final.npz"
    scene_file = scene_with(tmp_path, LOCKSTEP_SCENE, LOCKSTEP_AGENTS // 2)
    argvs = lockstep_argvs(scene_file, LOCKSTEP_AGENTS, out)
    _, texts, root, dropped = hr.run_on_hosts(net, tmp_path, argvs, lossy(net, LOSSY_HOST))
    hr.check_lockstep_on_hosts(scene_file, texts, out, LOCKSTEP_AGENTS)
    assert dropped > 20, f"the loss rule dropped {dropped} packets: too few to test repair"
    assert root.matched() == 0, "the root namespace's interfaces saw DDS packets"
    print(f"\nlockstep, {LOCKSTEP_AGENTS} agents on 3 hosts, {dropped} packets dropped into h1: "
          f"{time.monotonic() - started:.1f} s")


def test_realtime_converges_under_loss_and_delay(net, tmp_path):
    started = time.monotonic()
    scene_file = scene_with(tmp_path, hr.REALTIME_SCENE, hr.AGENTS)
    out = tmp_path / "final.npz"
    argvs = hr.realtime_argvs(scene_file, out, "--delay", 0.05)
    started_procs, _, root, dropped = hr.run_on_hosts(net, tmp_path, argvs, lossy(net, LOSSY_HOST))
    _check_converged(scene_file, started_procs, out)
    _check_clock_offsets(out)
    assert dropped > 20, f"the loss rule dropped {dropped} packets: too few to matter"
    assert root.matched() == 0, "the root namespace's interfaces saw DDS packets"
    print(f"\nrealtime, {hr.AGENTS} agents on 3 hosts, {LOSS}% loss ({dropped} packets), 50 ms "
          f"delay: {time.monotonic() - started:.1f} s")


def _check_clock_offsets(out):
    """Every agent estimated the clock offset of every peer from its pose stamps; the hosts share
    one clock, so each is near zero (the transport delay and a peer's lag behind its schedule
    only; a wrong time scale or sign would be seconds off)."""
    agents = []
    for host in range(3):
        with open(f"{out}.h{host}.jsonl") as fh:
            agents += [r for r in run_records(fh) if r.role == "agent"]
    assert len(agents) == 3, agents
    for rec in agents:
        assert sorted(rec.clock_offsets) == sorted(rec.peers), rec
        worst = max(abs(v) for v in rec.clock_offsets.values())
        assert worst < 0.5, f"{rec.name()}: clock offsets {rec.clock_offsets}"


def link_down_while_running(net):
    """``during``: once the monitor hears all agents, host DOWN_HOST's link goes down for
    DOWN_SECONDS; returns the monitor's records (heard before, in the outage once the monitor's
    peer timeout has passed, after it)."""

    def outage(procs, started, env):
        echo_env = discovery.discovery_environments("subnet").for_role("client", env)
        echo = procs.start([sys.executable, "-m", "polymatch_ros.cli", "echo",
                            "/polymatch/status", "--json", "--timeout", "150"], echo_env, 160,
                           "echo",
                           prefix=net.prefix(2))
        running = hr.wait_for_record(procs, echo, lambda r: r.agents_heard == hr.AGENTS
                                      and r.t >= 2.0 * hr.TIME_SCALE, 90)
        assert running, procs.output(echo)[-2000:]
        net.link_down(DOWN_HOST)
        down = time.monotonic()
        time.sleep(hr.PEER_TIMEOUT + 1.0)
        timed_out = len(hr.status_records(procs, echo))    # the monitor has dropped host 0
        time.sleep(max(0.0, down + DOWN_SECONDS - time.monotonic()))
        back = len(hr.status_records(procs, echo))
        net.link_up(DOWN_HOST)
        for proc in started:
            proc.wait(timeout=150)
        records = hr.status_records(procs, echo)
        return records[:timed_out], records[timed_out:back], records[back:]

    return outage


def test_realtime_link_down_then_rejoin(net, tmp_path):
    started = time.monotonic()
    scene_file = scene_with(tmp_path, hr.REALTIME_SCENE, hr.AGENTS)
    out = tmp_path / "final.npz"
    procs, _, root, (before, outage, after) = hr.run_on_hosts(
        net, tmp_path, hr.realtime_argvs(scene_file, out), link_down_while_running(net))
    others = hr.AGENTS - hr.AGENTS // 3
    assert any(r.agents_heard == hr.AGENTS for r in before)
    assert len(outage) >= 5, f"{len(outage)} monitor reports in {DOWN_SECONDS:g} s"
    assert {r.agents_heard for r in outage} == {others}, [r.agents_heard for r in outage]
    rejoined = [i for i, r in enumerate(after) if r.agents_heard == hr.AGENTS]
    assert rejoined, [r.agents_heard for r in after]
    # apart, the two sides each matched on a pose of their own: rejoined, they are apart
    assert after[rejoined[0]].diameter > 100 * load_scene(scene_file).tolerance
    _check_converged(scene_file, procs, out)
    assert root.matched() == 0, "the root namespace's interfaces saw DDS packets"
    print(f"\nrealtime, {hr.AGENTS} agents on 3 hosts, h{DOWN_HOST} down {DOWN_SECONDS:g} s: "
          f"{time.monotonic() - started:.1f} s")
