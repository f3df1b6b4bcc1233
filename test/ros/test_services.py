"""Start, stop, pause, reset through std_srvs services (``wire.control``), called by an rclpy
client the way ``ros2 service call`` calls them: the ensemble's services (hosted by the
monitor) and one agent's own.

Lockstep keeps the trajectory of the centralised run (Theorem 4.2's scene, stopped at the same
step by every process); realtime agents hold their state while paused and go back to the
initial state on reset.
"""

import os
import re

import numpy as np
import pytest
from ros_harness import PY, cli_argv, needs_ros, scene_path

from benchmarks.hosts.runs import scene_with
from polymatch_ros.core.scenes.scene import load_scene
from polymatch_ros.ros.wire import run_records

pytestmark = needs_ros

SCENE = "congruent_triangles"
N = 4  # of the scene's triangles: the services, not the count, are under test
PROBE = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "support",
                     "service_probe.py")
BOUND = 150  # s: only a hang takes this long


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    """The scene with ``N`` agents, a process each where a test starts one per agent."""
    return scene_with(tmp_path_factory.mktemp("scene"), scene_path(SCENE), N)


def _probe(ros, *actions, timeout=BOUND, beside=None):
    """The probe's output; on failure also the tail of ``beside``'s (the run it probes)."""
    proc = ros.start([PY, PROBE, *actions], timeout=timeout, name="probe")
    rc = ros.wait(proc, timeout + 10)
    text = ros.output(proc)
    run = "" if beside is None else "\n--- the run:\n" + ros.output(beside)[-4000:]
    assert rc == 0, text + run
    return text


def _results(text):
    """[(service, success, message)] of every call the probe made, in order."""
    return [(m[0], m[1] == "True", m[2]) for m in re.findall(r"^RESULT (\S+) (\S+) ?(.*)$",
                                                            text, re.M)]


def _times(text):
    return [float(v) for v in re.findall(r"^T (\S+)$", text, re.M)]


def _poses(text):
    """[(stamp, x, y)] of every pose the probe printed."""
    rows = re.findall(r"^POSE (\S+) (\S+) (\S+) ", text, re.M)
    return [tuple(float(v) for v in row) for row in rows]


def test_lockstep_pause_holds_every_process_and_stop_ends_all_at_the_same_step(ros, scene):
    ros.monitor(scene, timeout=BOUND, t_end=1000.0)
    agents = [ros.agent(scene, i, timeout=BOUND, t_end=1000.0) for i in range(N)]
    text = _probe(
        ros,
        "until_t 0.5",
        "call /polymatch/reset",
        "call /polymatch/agent_2/pause true",  # one process paused: its peers wait for it
        "t",
        "sleep 2",
        "t",
        "call /polymatch/agent_2/pause false",
        "sleep 1",
        "t",
        "call /polymatch/stop",
    )
    (reset, _, why), pause, resume, stop = _results(text)
    assert not _results(text)[0][1] and "reproducible" in why, text
    assert pause[1] and resume[1] and stop[1], text
    paused, still_paused, resumed = _times(text)
    assert paused == still_paused < resumed, text
    for a in agents:
        assert ros.wait(a, 60) == 0, ros.output(a)[-2000:]
    finals = [run_records(ros.output(a).splitlines())[-1] for a in agents]
    assert all(r.finished for r in finals)
    assert len({r.steps for r in finals}) == 1 and len({r.t for r in finals}) == 1, finals
    assert finals[0].t < 1000.0


def test_realtime_pause_holds_the_state_reset_returns_to_it_and_the_run_converges(ros, scene):
    """Through ``polymatch run`` (which starts and stops the ensemble by its services); a
    process per agent (-k 1), so that agent_0 is a lifecycle node of its own."""
    run = ros.start(
        cli_argv("run", scene, "--mode", "realtime", "--rate", "20",
                 "--time-scale", "2", "--t-end", "80", "--timeout", str(BOUND), "-k", "1"),
        timeout=BOUND + 20,
        name="runner",
    )
    text = _probe(
        ros,
        "until_t 2",
        "state /polymatch/agent_0",  # the runner configured and activated it (autostart off)
        "call /polymatch/pause true",
        "sleep 1",
        "pose 0",
        "sleep 1",
        "pose 0",
        "call /polymatch/reset",
        "sleep 1.5",
        "pose 0",
        "call /polymatch/pause false",
        "sleep 1",
        "pose 0",
        beside=run,
    )
    assert all(ok for _, ok, _ in _results(text)), text
    assert re.findall(r"^STATE (\S+)$", text, re.M) == ["active"], text
    held_a, held_b, reset, resumed = _poses(text)
    assert held_a[1:] == held_b[1:] and held_b[0] > held_a[0], text  # held, on the clock
    loaded = load_scene(scene)
    initial = loaded.initial.groups[0].x[0] + loaded.origin
    assert np.allclose(reset[1:], initial, rtol=0, atol=1e-12), (reset, initial)
    assert held_a[1:] != reset[1:] and resumed[1:] != reset[1:] and resumed[0] > reset[0]
    rc = ros.wait(run, BOUND + 30)
    out = ros.output(run)
    assert rc == 0 and "converged" in out, out[-3000:]


def test_a_run_stopped_by_the_stop_service_says_so_and_exits_4(ros, scene):
    """``polymatch run`` in lockstep, its ensemble stopped from outside (as by ``ros2 service
    call /polymatch/stop``) long before it converges: every process ends, and the run reports
    ``stopped by request``, not that it did not converge at t_end."""
    run = ros.start(
        # a process per agent (-k 1): fast enough to stop mid-run, slow enough not to converge
        cli_argv("run", scene, "--t-end", "1000", "--timeout", str(BOUND), "-k", "1"),
        timeout=BOUND + 20,
        name="runner",
    )
    text = _probe(ros, "until_t 0.5", "call /polymatch/stop", beside=run)
    assert [(name, ok) for name, ok, _ in _results(text)] == [("/polymatch/stop", True)], text
    rc = ros.wait(run, BOUND + 30)
    out = ros.output(run)
    stopped = re.search(r"^stopped by request at t = (\S+) \(the ensemble's stop service, "
                        r"called at t = (\S+)\): matching diameter (\S+), tolerance", out, re.M)
    assert rc == 4 and stopped, out[-3000:]
    assert 0.5 <= float(stopped.group(1)) < 1000 and float(stopped.group(2)) >= 0.5
    assert float(stopped.group(3)) >= load_scene(scene).tolerance
    assert "did not converge" not in out


STOP_TIME = """
import sys
import rclpy
from polymatch_ros.core.scenes.scene import load_scene
from polymatch_ros.ros.wire.control import command_message
from polymatch_ros.ros.supervisor.watcher import Watcher
from polymatch_ros.ros.wire import RunRecord

monitor_t, agents_t = float(sys.argv[2]), [float(t) for t in sys.argv[3:]]
rclpy.init()
watcher = Watcher(load_scene(sys.argv[1]), "polymatch", run_id=7)
def status(**record):
    watcher._status(RunRecord(mode="lockstep", run_id=7, **record).to_msg())
status(role="monitor", t=monitor_t)
for a, t in enumerate(agents_t):
    status(role="agent", agents=(a,), t=t)
watcher._control(command_message("stop"))
print(f"STOP {watcher.stop_requested_at!r}", flush=True)
watcher.node.destroy_node()
rclpy.shutdown()
"""


@pytest.mark.parametrize("monitor_t, agents_t, dated", [
    (0.45, [0.6] * N, 0.6),                  # the monitor's report is one behind the records
    (0.75, [0.6] * N, 0.75),                 # the records are the staler
    (0.45, [0.6] * (N - 1), 0.45),           # an agent not yet heard: the monitor's alone
])
def test_a_stop_is_dated_at_the_latest_time_every_agent_is_known_to_have_reached(
        ros, scene, monitor_t, agents_t, dated):
    """``stopped by request ... called at t``: the runner dates a stop it did not send at the
    later of its two lower bounds of the ensemble's time, so a stop called once every agent's
    run record said t (as the test above calls it) is never dated before t."""
    args = [scene, monitor_t, *agents_t]
    proc = ros.start([PY, "-c", STOP_TIME, *args], timeout=60, name="watcher")
    rc = ros.wait(proc, 70)
    out = ros.output(proc)
    assert rc == 0 and f"STOP {dated!r}" in out, out[-2000:]


def test_lifecycle_agent_walks_every_transition_and_steps_only_when_active(ros, scene):
    """A managed agent (autostart off) through lifecycle_msgs ChangeState: unconfigured it has
    no pose topic; configured it has one but is silent; cleanup removes it; active it moves;
    deactivated it holds its pose on the clock; activated again it moves; shutdown ends it."""
    realtime = dict(mode="realtime", start="now", rate=20.0, t_end=1000.0, timeout=BOUND)
    managed = ros.agent(scene, 0, autostart=False, **realtime)
    ros.agent(scene, 1, **realtime)  # a peer, so that agent 0 has something to match
    node, topic = "/polymatch/agent_0", "/polymatch/agent_0/pose"
    text = _probe(
        ros,
        f"state {node}", f"publishers {topic} 0",
        f"lifecycle {node} configure", f"state {node}", f"publishers {topic} 1", "silent 0 1.5",
        f"lifecycle {node} cleanup", f"state {node}", f"publishers {topic} 0",
        f"lifecycle {node} configure", f"lifecycle {node} activate", f"state {node}",
        "pose 0", "sleep 1", "pose 0",
        f"lifecycle {node} deactivate", "sleep 0.5", "pose 0", "sleep 1", "pose 0",
        f"lifecycle {node} activate", "sleep 1", "pose 0",
        f"lifecycle {node} shutdown",
    )
    states = re.findall(r"^STATE (\S+)$", text, re.M)
    assert states == ["unconfigured", "inactive", "unconfigured", "active"], text
    assert re.findall(r"^PUBLISHERS (\d+)$", text, re.M) == ["0", "1", "0"], text
    assert "SILENT True" in text, text
    transitions = re.findall(r"^LIFECYCLE (\S+) (\S+)$", text, re.M)
    assert len(transitions) == 7 and all(ok == "True" for _, ok in transitions), text
    moving_a, moving_b, held_a, held_b, again = _poses(text)
    assert moving_a[1:] != moving_b[1:], text
    assert held_a[1:] == held_b[1:] and held_b[0] > held_a[0], text
    assert again[1:] != held_b[1:], text
    assert ros.wait(managed, 30) == 0, ros.output(managed)[-2000:]


def test_polymatch_set_changes_a_runtime_gain_on_every_agent_in_one_command(ros, tmp_path):
    """``polymatch set kappa 1.5``: every realtime agent of the ensemble accepts it (its
    set_parameters service) and applies it at its next tick; a value out of range is refused
    before anything is sent.  The ensemble is the scene's two agents: `polymatch set` calls
    once their run records and nodes have all been found (one node found later than the other
    on a loaded machine once made it set one of two)."""
    two = tmp_path / "two.yaml"
    with open(scene_path(SCENE), encoding="utf-8") as fh:
        two.write_text(fh.read().replace("count: 8", "count: 2"), encoding="utf-8")
    assert load_scene(two).model.n_agents == 2
    realtime = dict(mode="realtime", start="now", rate=20.0, t_end=1000.0, timeout=BOUND)
    agents = [ros.agent(str(two), i, **realtime) for i in range(2)]
    _probe(ros, "pose 0", "pose 1")  # both active and publishing
    setter = ros.start(cli_argv("set", "kappa", "1.5", "--timeout", "30"), timeout=60,
                       name="set")
    assert ros.wait(setter, 70) == 0, ros.output(setter)
    applied = re.findall(r"^(agent_\d): kappa = 1.5 ", ros.output(setter), re.M)
    assert applied == ["agent_0", "agent_1"], ros.output(setter)
    _probe(ros, "sleep 1")
    for a in agents:
        assert "kappa 1 -> 1.5" in ros.output(a), ros.output(a)[-2000:]
    bad = ros.start(cli_argv("set", "kappa", "2e6"), timeout=30, name="set_bad")
    assert ros.wait(bad, 40) == 2 and "out of range" in ros.output(bad), ros.output(bad)
