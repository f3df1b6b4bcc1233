"""A host that dies and comes back, and a lockstep agent killed on a non-lead host, across
three network-namespace hosts.

Realtime, 12 agents 4/4/4: host 1's runner and its agents are killed (SIGKILL, the whole
process tree) mid-run. The other hosts' agents keep running (the monitor on host 2 reports the
8 agents it still hears); `polymatch run --only 4-7` started again on host 1 waits for its
killed nodes to leave the ROS graph (their DDS lease) where it sees them, brings its agents
back (at once: the ensemble already runs), and the ensemble matches. The monitor's reports are
read as data (its ``status`` run records, through `polymatch echo` inside host 2); tcpdump on
the root namespace must see no DDS packet.

Lockstep, 12 agents 4/4/4: host 1's agent process is killed mid-run; host 1's runner restarts
it, it resumes from its checkpoint, and the run equals the centralised one to 1e-9.
"""

import contextlib
import os
import re
import signal
import sys
import time

import pytest
from host_runs import (
    AGENTS,
    PEER_TIMEOUT,
    REALTIME_SCENE,
    TIME_SCALE,
    check_lockstep_on_hosts,
    realtime_argvs,
    run_on_hosts,
    saved_diameter,
    status_records,
    three_hosts,
    wait_for_record,
)
from ros_harness import needs_ros, scene_path
from shm_watch import ShmWatch

from benchmarks.hosts.runs import argv_of, descendants, lockstep_argvs, node_name, scene_with
from polymatch_ros.core.scenes.scene import load_scene
from polymatch_ros.ros.network import discovery

pytestmark = needs_ros

KILLED_HOST = 1
T_END = 150.0        # 50 s at time scale 3: room for the killed host's return
TIMEOUT = 150        # s, each host's run


@pytest.fixture
def net():
    yield from three_hosts()


def kill_tree(pid):
    """SIGKILL a process and every process under it (a host's runner and its agents)."""
    for child in [pid] + descendants(pid):
        with contextlib.suppress(ProcessLookupError):
            os.kill(child, signal.SIGKILL)


def kill_and_restart_host(net, argv):
    """``during``: once the monitor hears all agents, kill host KILLED_HOST's process tree;
    once it reports the others alone, start the host's run again. Returns (the monitor's
    records, the index of the first after the kill, the restarted run, its output)."""

    def during(procs, started, env):
        # the /dev/shm entries of every process of this test, noted while they live
        shm = ShmWatch(lambda: [p.pid for p in procs.procs if p.poll() is None])
        echo_env = discovery.discovery_environments("subnet").for_role("client", env)
        echo = procs.start([sys.executable, "-m", "polymatch_ros.cli", "echo",
                            "/polymatch/status", "--json", "--timeout", str(TIMEOUT)], echo_env,
                           TIMEOUT + 10, "echo",
                           prefix=net.prefix(2))
        assert wait_for_record(procs, echo, lambda r: r.agents_heard == AGENTS
                               and r.t >= 2.0 * TIME_SCALE, 90), procs.output(echo)[-2000:]
        shm.look()
        kill_tree(started[KILLED_HOST].pid)
        killed = len(status_records(procs, echo))
        others = AGENTS - AGENTS // 3
        assert wait_for_record(procs, echo, lambda r: r.agents_heard == others,
                               PEER_TIMEOUT + 20), [r.agents_heard for r in
                                                    status_records(procs, echo)]
        again = procs.start(argv, env, TIMEOUT + 10, f"h{KILLED_HOST}-again",
                            prefix=net.prefix(KILLED_HOST))
        for proc in (started[0], started[2], again):
            proc.wait(timeout=TIMEOUT + 20)
        shm.stop()
        return status_records(procs, echo), killed, again, procs.output(again), shm

    return during


def test_realtime_host_killed_then_run_again_rejoins_and_matches(net, tmp_path):
    started = time.monotonic()
    scene_file = scene_with(tmp_path, REALTIME_SCENE, AGENTS)
    out = tmp_path / "final.npz"
    argvs = realtime_argvs(scene_file, out, t_end=T_END, timeout=TIMEOUT)
    during = kill_and_restart_host(net, argvs[KILLED_HOST])
    procs, texts, root, (records, killed, again, again_text, shm) = run_on_hosts(
        net, tmp_path, argvs, during, seconds=TIMEOUT + 10, check=False)
    assert procs[KILLED_HOST].returncode == -signal.SIGKILL, procs[KILLED_HOST].returncode
    others = AGENTS - AGENTS // 3
    after = [r.agents_heard for r in records[killed:]]
    assert others in after, after                           # the others went on alone ...
    back = after.index(others)
    assert AGENTS in after[back:], after                    # ... until host 1 was back
    # its killed nodes linger in the graph (DDS lease) if discovery saw them: waited for, never
    # refused
    assert "already runs in this ROS domain" not in again_text, again_text[-2000:]
    assert again.returncode == 0, again_text[-3000:]
    assert procs[0].returncode == 0, texts[0][-3000:]
    assert procs[2].returncode == 0, texts[2][-3000:]
    assert "converged" in texts[2], texts[2][-3000:]
    tolerance = load_scene(scene_file).tolerance
    assert saved_diameter(scene_file, out) < tolerance
    assert root.matched() == 0, "the root namespace's interfaces saw DDS packets"
    # nothing left behind: the killed runner's temporary folder is in the run's own folder
    # (the three others removed theirs), and no process of the run left a file in /dev/shm
    assert len(list(tmp_path.glob("polymatch_run_*"))) == 1, sorted(tmp_path.iterdir())
    assert shm.left() == [], shm.left()
    print(f"\nrealtime, {AGENTS} agents on 3 hosts, h{KILLED_HOST} killed and run again: "
          f"{time.monotonic() - started:.1f} s")


LOCKSTEP_SCENE = "mixed_triangles_tetrahedra"     # 12 agents: 4/4/4, one process a host
# long enough that the kill, at 30% of it on the lead's progress lines, lands mid-run (a run
# of t_end 3 was over too soon)
LOCKSTEP_T_END = 12.0
PROGRESS = re.compile(r"^t = +(\S+) /", re.M)
RESTARTED = re.compile(r"^  agents_4_7 \(pid (\d+)\) killed by SIGKILL at t = \S+; restarted "
                       r"after \S+ s as pid \d+, back after \S+ s", re.M)


def test_lockstep_agent_killed_on_a_non_lead_host_resumes_exactly_theorem_4_2(net, tmp_path):
    """Lockstep, 12 agents 4/4/4: SIGKILL of host 1's agent process mid-run. Host 1's runner
    restarts it, it resumes from its checkpoint (its peers on the other hosts keep the rounds
    it needs), and the lead's summary and saved poses equal the centralised run to 1e-9."""
    out = tmp_path / "final.npz"
    argvs = lockstep_argvs(LOCKSTEP_SCENE, AGENTS, out, t_end=LOCKSTEP_T_END, timeout=TIMEOUT)

    def during(procs, started, env):
        deadline = time.monotonic() + 90
        while time.monotonic() < deadline:
            shown = PROGRESS.findall(procs.output(started[2]))
            if shown and float(shown[-1]) >= 0.3 * LOCKSTEP_T_END:
                break
            assert all(p.poll() is None for p in started), procs.output(started[2])[-3000:]
            time.sleep(0.1)
        victims = [pid for pid in descendants(started[KILLED_HOST].pid)
                   if node_name(argv_of(pid)) == "agents_4_7"]
        assert len(victims) == 1, procs.output(started[KILLED_HOST])[-3000:]
        os.kill(victims[0], signal.SIGKILL)
        return victims[0]

    _, texts, root, victim = run_on_hosts(net, tmp_path, argvs, during, seconds=TIMEOUT)
    restarted = RESTARTED.search(texts[KILLED_HOST])
    assert restarted and int(restarted.group(1)) == victim, texts[KILLED_HOST][-3000:]
    check_lockstep_on_hosts(scene_path(LOCKSTEP_SCENE), texts, out, AGENTS)
    assert root.matched() == 0, "the root namespace's interfaces saw DDS packets"
