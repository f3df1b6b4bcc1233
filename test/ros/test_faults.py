"""No single crash ends a run: `polymatch run` under faults (``--on-failure``, ``recovery``).

Each test signals a process of a running ensemble by its PID (SIGKILL: dead; SIGSTOP then
SIGCONT: hung, not dead; SIGTERM to the runner: ended early) and asserts the outcome the
README's table promises: lockstep resumes exactly (the run still equals the centralised
simulation, Theorem 4.2's scene), realtime converges, the summary lists each death, and no
process is left over.
"""

import os
import re
import signal
import time

import numpy as np
import pytest
from exactness import central_vertices, received_vertices
from ros_harness import PY, cli_argv, needs_ros, placed_vertices, scene_path
from shm_watch import ShmWatch

from benchmarks.hosts.runs import argv_of, children, descendants, node_name, scene_with
from polymatch_ros.core.saved import load_saved
from polymatch_ros.core.scenes.scene import load_scene
from polymatch_ros.core.stepping.simulate import choose_numerics, simulate
from polymatch_ros.ros.wire import run_records

pytestmark = needs_ros

SCENE = "congruent_triangles"
PROBE = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "support",
                     "service_probe.py")
BOUND = 150  # s: only a hang takes this long
BRIDGE_AGENTS = 3  # robots in a bridge run: agents 1 and 2 take the faults, agent 0 looks on
SERVER_MODULE = b"polymatch_ros.ros.network.discovery_server"
DEVIATION = re.compile(r"max vertex deviation (\S+)")
FAILURE = re.compile(r"^  (\S+) \(pid (\d+)\) (killed by \w+|exit code -?\d+|hung \(stopped\) "
                     r"for)[^;]*? (?:at t = (\S+)|"
                     r"before the ensemble's clock started); restarted after \S+ s as pid (\d+), "
                     r"back after \S+ s", re.M)

AFTER_RUN = re.compile(r"^  (\S+) \(pid (\d+)\) killed by SIGKILL at t = (\S+) after its run "
                       r"had ended, its final states in; not restarted$", re.M)


def _pid_where(run, wanted, what):
    """The PID of the first process below ``run`` whose command line ``wanted`` accepts."""
    for pid in descendants(run.pid):
        if wanted(argv_of(pid)):
            return pid
    raise AssertionError(f"no {what} below pid {run.pid}")


def _process(run, node):
    """The PID of the run's process whose node is ``node`` (``-r __node:=<node>``)."""
    return _pid_where(run, lambda argv: node_name(argv) == node, f"process of node {node}")


def _server(run):
    """The PID of the run's own discovery server (below its `timeout` wrapper)."""
    return _pid_where(run, lambda argv: SERVER_MODULE in argv and b"timeout" not in argv,
                      "discovery server")


def _runner(run):
    """The `polymatch run` process below the harness's `timeout` wrapper."""
    below = children(run.pid)
    assert len(below) == 1, below
    return below[0]


def _until(ros, t, run):
    """Wait until every agent reached simulated time ``t`` (the service probe)."""
    probe = ros.start([PY, PROBE, f"until_t {t}"], timeout=BOUND, name="probe")
    assert ros.wait(probe, BOUND + 10) == 0, ros.output(probe) + ros.output(run)[-3000:]


def _run(ros, *args, scene=None):
    """`polymatch run` of ``scene`` (default: the shipped SCENE, 8 agents)."""
    return ros.start(cli_argv("run", scene or scene_path(SCENE), "--timeout", BOUND, *args),
                     timeout=BOUND + 20, name="runner")


def _bridge_scene(tmp_path):
    """SCENE with BRIDGE_AGENTS agents: a bridge run has a robot process beside each agent's."""
    return scene_with(tmp_path, SCENE, BRIDGE_AGENTS)


def _finish(ros, run):
    rc = ros.wait(run, BOUND + 30)
    return rc, ros.output(run)


def _gone(pids):
    """None of ``pids`` still runs (zombies of a live parent do not count)."""
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        alive = [p for p in pids if os.path.exists(f"/proc/{p}") and not _zombie(p)]
        if not alive:
            return True
        time.sleep(0.2)
    return False


def _zombie(pid):
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] == "Z"
    except OSError:
        return False


def _lockstep_scene(dt, t_end):
    """SCENE at the run's step and end time, and the method its distributed run uses."""
    scene = load_scene(scene_path(SCENE), {"integrator.dt": dt, "time.t_end": t_end})
    return scene, choose_numerics(scene, None, None, distributed=True).name


def _assert_saved_equal_centralised(save, dt, t_end=None):
    """The final poses the runner saved are at t_end (if given: else where the run stopped) and,
    vertex by vertex (brute force over agents and vertices), within 1e-9 of the centralised
    run's at that time."""
    t = load_saved(save).t
    if t_end is not None:
        assert t == pytest.approx(t_end)
    scene, method = _lockstep_scene(dt, t)
    t, got = received_vertices(scene, save)
    want = central_vertices(scene, method, t)
    dev = max(float(np.max(np.linalg.norm(a - b, axis=-1))) for a, b in zip(got, want))
    assert dev <= 1e-9, f"saved poses {dev:.3e} from the centralised run"



def test_lockstep_resumes_exactly_after_processes_die_or_hang_theorem_4_2(ros, tmp_path):
    """Lockstep, four processes (round timeout 4 s): one hangs 2 s (SIGSTOP, SIGCONT) and is
    waited for; then, together, one is killed (SIGKILL) and one hangs for good, taken for dead
    after the round timeout.  The two are restarted and resume from their checkpoints (one
    may resume a step before the other: the other's checkpoint brings back the messages it
    needs), and the final poses equal the centralised run's to 1e-9.  The monitor, killed
    with them, is restarted; the rounds never wait for it."""
    # t_end 6 (300 steps): the probes that time the faults need a few seconds each, and the
    # four processes' rounds are fast
    save = tmp_path / "final.npz"
    run = _run(ros, "--t-end", "6", "--dt", "0.02", "-k", "2", "--round-timeout", "4",
               "--save", save)
    shm = ShmWatch(lambda: [run.pid])  # the run's processes' /dev/shm entries
    _until(ros, 0.3, run)
    slow = _process(run, "agents_4_5")
    os.kill(slow, signal.SIGSTOP)
    time.sleep(2)
    os.kill(slow, signal.SIGCONT)
    victim, hung = _process(run, "agents_2_3"), _process(run, "agents_0_1")
    _until(ros, 0.8, run)
    monitor = _process(run, "monitor")
    shm.look()
    os.kill(monitor, signal.SIGKILL)
    os.kill(victim, signal.SIGKILL)
    os.kill(hung, signal.SIGSTOP)
    before = descendants(run.pid)
    rc, out = _finish(ros, run)
    shm.stop()
    assert rc == 3 and "did not converge" in out, out[-3000:]  # t_end 6 is before matching
    assert float(DEVIATION.search(out).group(1)) <= 1e-9, out[-3000:]
    failures = FAILURE.findall(out)
    assert sorted((f[0], int(f[1]), f[2]) for f in failures) == [
        ("agents_0_1", hung, "hung (stopped) for"),
        ("agents_2_3", victim, "killed by SIGKILL"),
        ("monitor", monitor, "killed by SIGKILL")], out[-3000:]
    assert all(float(f[3]) >= 0.8 for f in failures if f[0] != "monitor"), out[-3000:]
    steps = [int(s) for s in re.findall(r"resumed at step (\d+)", out)]
    assert len(steps) == 2 and all(40 <= s < 300 for s in steps), out[-3000:]
    assert "failures: 3 process death(s), 3 restarted" in out
    assert _gone(before + [int(f[4]) for f in failures])
    # the killed processes' Fast DDS segments (seen while they ran) are gone with the others'
    assert shm.of(victim) and shm.of(monitor), shm.seen
    assert shm.left() == [], shm.left()
    _assert_saved_equal_centralised(save, 0.02, 6.0)


def test_a_lockstep_process_killed_after_its_run_ended_is_not_restarted_theorem_4_2(ros,
                                                                                     tmp_path):
    """Lockstep, four processes, the monitor stopped (SIGSTOP) before the end: no agent is
    told 'received', so each holds its final poses.  SIGKILL of one of them once the runner
    has every final state: it is listed, not restarted (a restarted one would begin a step
    its peers have ended), the monitor is not waited for, and the run ends as it would have:
    equal to the centralised run, exit 3 (t_end 3 is before matching), nothing left over."""
    save = tmp_path / "final.npz"
    run = _run(ros, "--t-end", "3", "--dt", "0.02", "-k", "2", "--save", save)
    _until(ros, 0.3, run)
    monitor = _process(run, "monitor")
    os.kill(monitor, signal.SIGSTOP)
    try:
        _until(ros, 2.99, run)
        time.sleep(2)  # the runner takes the final states every 0.2 s once a process finished
        victim = _process(run, "agents_2_3")
        before = descendants(run.pid)
        os.kill(victim, signal.SIGKILL)
        time.sleep(1)
    finally:
        os.kill(monitor, signal.SIGCONT)
    rc, out = _finish(ros, run)
    assert rc == 3 and "did not converge" in out, out[-3000:]
    assert float(DEVIATION.search(out).group(1)) <= 1e-9, out[-3000:]
    assert AFTER_RUN.findall(out) == [("agents_2_3", str(victim), "3")], out[-3000:]
    assert "failures: 1 process death(s), 0 restarted" in out, out[-3000:]
    assert _gone(before)
    _assert_saved_equal_centralised(save, 0.02, 3.0)


def test_realtime_converges_after_an_agent_and_the_monitor_are_killed(ros, tmp_path):
    """Realtime, 8 agents two a process: SIGKILL of agents 2-3, then of the monitor; both are
    restarted, the agents rejoin the ensemble's clock from their last state and the run
    converges (exit 0); ``--run-records`` lists both deaths.  Agents 4-5, stopped (SIGSTOP) for
    2 s in between, are waited out (their peers go on without them), never killed."""
    records = tmp_path / "records.jsonl"
    run = _run(ros, "--mode", "realtime", "--rate", "20", "--time-scale", "4", "--t-end", "300",
               "--run-records", records, "-k", "2")
    _until(ros, 4, run)
    os.kill(_process(run, "agents_2_3"), signal.SIGKILL)
    hung = _process(run, "agents_4_5")
    os.kill(hung, signal.SIGSTOP)
    time.sleep(2)
    os.kill(hung, signal.SIGCONT)
    _until(ros, 12, run)
    os.kill(_process(run, "monitor"), signal.SIGKILL)
    rc, out = _finish(ros, run)
    assert rc == 0 and "converged" in out, out[-3000:]
    assert [f[0] for f in FAILURE.findall(out)] == ["agents_2_3", "monitor"], out[-3000:]
    lines = records.read_text().splitlines()
    deaths = [line for line in lines if line.startswith('{"polymatch_failure"')]
    assert len(deaths) == 2 and '"code": -9' in deaths[0], lines
    assert len(run_records(lines)) >= 2  # the run records are still readable around them


def test_bridge_run_survives_every_fault_of_the_matrix(ros, tmp_path):
    """Bridge, 3 robots, ``--discovery server``: SIGKILL of the discovery server, of agent 1's
    process and of the monitor, SIGSTOP of agent 2's for 2 s (then SIGCONT). The dead are
    restarted (the agent takes its robot's measured pose, and finds its peers through the
    restarted server), the hung one is waited for, not killed, and the robots match to the
    noise floor (exit 0); the summary lists the three deaths and nothing else.  The robots
    can match by t = 7: ``--hold 12`` keeps the run going past the last fault (at t = 10 to 12,
    real time), to t = 19 at the earliest."""
    run = _run(ros, "--mode", "bridge", "--rate", "10", "--t-end", "120", "--discovery", "server",
               "--hold", "12", scene=_bridge_scene(tmp_path))
    _progress_past(ros, run, 2)
    os.kill(_server(run), signal.SIGKILL)
    # progress lines come about every 2 s of the run: the one past 2 may already be past 4, and
    # two deaths noticed in one pass of the runner's loop are listed agents first
    _progress_past(ros, run, 6)
    os.kill(_process(run, "agent_1"), signal.SIGKILL)
    hung = _process(run, "agent_2")
    os.kill(hung, signal.SIGSTOP)
    time.sleep(2)
    os.kill(hung, signal.SIGCONT)
    _progress_past(ros, run, 10)
    os.kill(_process(run, "monitor"), signal.SIGKILL)
    rc, out = _finish(ros, run)
    assert rc == 0 and "converged" in out, out[-3000:]
    assert [f[0] for f in FAILURE.findall(out)] == ["discovery_server", "agent_1", "monitor"], (
        out[-3000:])


def test_on_failure_stop_ends_the_run_at_the_first_death(ros):
    """``--on-failure stop``: the first death ends every process, exit 1, naming it."""
    run = _run(ros, "--mode", "realtime", "--rate", "20", "--on-failure", "stop", "-k", "2")
    _until(ros, 1, run)
    victim = _process(run, "agents_4_5")
    before = descendants(run.pid)
    os.kill(victim, signal.SIGKILL)
    rc, out = _finish(ros, run)
    assert rc == 1, out[-3000:]
    assert re.search(rf"polymatch: error: agents_4_5 \(pid {victim}\) exited with code -9", out)
    assert "not restarted" in out and _gone(before)


EARLY_END_OPTIONS = {"lockstep": ["--dt", "0.02", "-k", "4"],
                     "realtime": ["--mode", "realtime", "--rate", "20", "-k", "4"],
                     "bridge": ["--mode", "bridge", "--rate", "10"]}  # 3 robots, 6 processes


@pytest.mark.parametrize("mode", list(EARLY_END_OPTIONS))
def test_a_run_ended_early_saves_each_agents_last_state_marked_partial(ros, tmp_path, mode):
    """SIGTERM to the runner mid-run: exit 130, and --save still holds every agent's last
    state, its time, and ``partial``; no process is left over."""
    save = tmp_path / "poses.npz"
    scene, n = (_bridge_scene(tmp_path), BRIDGE_AGENTS) if mode == "bridge" else (None, 8)
    run = _run(ros, "--t-end", "500", "--save", save, *EARLY_END_OPTIONS[mode], scene=scene)
    _until(ros, 0.5, run)
    before = descendants(run.pid)
    os.kill(_runner(run), signal.SIGTERM)
    rc, out = _finish(ros, run)
    assert rc == 130 and "partial state saved" in out, out[-3000:]
    saved = load_saved(save)
    assert saved.partial and 0.5 <= saved.t < 500
    data = saved.groups[0]
    times = data.agent_times
    assert times.shape == (n,) and np.all(times >= 0.5) and np.all(times < 500)
    assert saved.t == times.min()              # the earliest agent's time
    rotations = data.rotations[-1]
    assert np.allclose(rotations @ rotations.transpose(0, 2, 1), np.eye(2), atol=1e-12)
    assert np.allclose(np.linalg.det(rotations), 1.0, atol=1e-12)
    if mode == "lockstep":
        _assert_each_agent_at_its_time_is_the_centralised_run(data, times)
    assert _gone(before)


def _assert_each_agent_at_its_time_is_the_centralised_run(data, times):
    """Lockstep: agent i's saved pose is the centralised run's agent i at its own time t_i (the
    agents of a process share a step, processes may be a step apart), vertex by vertex."""
    scene, method = _lockstep_scene(0.02, float(times.max()))
    traj = simulate(scene, method, 0.02, samples=sorted(set(times.tolist())), metrics=False)
    at = {round(t, 9): st for t, st in zip(traj.times, traj.states)}
    reference = scene.model.groups[0].reference
    for i, t in enumerate(times):
        state = at[round(float(t), 9)]
        want = placed_vertices(traj.scene.model, state.groups, scene.origin)[0]  # vertex, agent
        got = data.centroids[-1][i] + reference @ data.rotations[-1][i].T
        assert np.max(np.linalg.norm(got - want[:, i], axis=-1)) <= 1e-9, (i, t)


def _progress_past(ros, run, t):
    """Wait until the run's progress line shows simulated time ``t`` or later."""
    deadline = time.monotonic() + BOUND
    while time.monotonic() < deadline:
        shown = re.findall(r"^t = +(\S+) /", ros.output(run), re.M)
        if shown and float(shown[-1]) >= t:
            return
        assert run.poll() is None, ros.output(run)[-3000:]
        time.sleep(0.2)
    raise AssertionError(f"no progress to t = {t}: " + ros.output(run)[-3000:])


# mode -> (its options, the simulated times at which the server and then an agent are killed)
SERVER_RUNS = {
    "realtime": (["--mode", "realtime", "--rate", "20", "--time-scale", "2", "--t-end", "300"],
                 2.0, 6.0),
    # dt 0.01: converges at t ~ 21 after 8,400 rounds, so that the run is still going when the
    # server is back (its restart takes seconds) and the agent is killed (at dt 0.05 a lockstep
    # run could reach its end meanwhile)
    "lockstep": (["--t-end", "60", "--dt", "0.01"], 0.2, 0.5),
}


@pytest.mark.parametrize("mode", list(SERVER_RUNS))
def test_a_restarted_discovery_server_is_found_again_by_a_restarted_agent(ros, tmp_path, mode):
    """``--discovery server``: SIGKILL of the run's discovery server, then of an agent process;
    the server is restarted on its address, the agent's new process discovers its peers
    through it, and the run converges (lockstep: still equal to the centralised run)."""
    options, server_at, agent_at = SERVER_RUNS[mode]
    save = tmp_path / "final.npz"
    run = _run(ros, *options, "-k", "4", "--discovery", "server", "--save", save)
    _progress_past(ros, run, server_at)  # a probe with loopback discovery would not see this run
    os.kill(_server(run), signal.SIGKILL)
    _progress_past(ros, run, agent_at)
    os.kill(_process(run, "agents_0_3"), signal.SIGKILL)
    rc, out = _finish(ros, run)
    assert rc == 0 and "converged" in out, out[-3000:]
    # lockstep runs fast: the runner may see both deaths in one look, in either order
    assert sorted(f[0] for f in FAILURE.findall(out)) == ["agents_0_3", "discovery_server"], (
        out[-3000:])
    if mode == "lockstep":
        assert float(DEVIATION.search(out).group(1)) <= 1e-9, out[-3000:]
        _assert_saved_equal_centralised(save, 0.01)
