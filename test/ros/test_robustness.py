"""Bad input from the network or the command line never poisons the ensemble.

- a rogue publisher on an agent's pose, stage, exchange and final topics (NaN, non-unit
  quaternions, foreign run ids, another run's final state) changes nothing in a lockstep
  result, and the drops are counted;
- another run's well-formed states of an agent change nothing in a realtime run;
- bad ROS parameters are one line and exit code 2;
- the package builds with colcon (from PyPI) in a scratch workspace and the installed
  `agent` and `monitor` executables start; a one-agent scene runs to t_end.
"""

import os
import pathlib
import re
import signal
import subprocess
import time
from dataclasses import replace

import numpy as np
import pytest
import yaml
from ros_harness import PY, REPO, _children, cli_argv, needs_ros, node_argv, scene_path
from shm_watch import fast_dds_names, private_shm_argv, private_shm_possible

from benchmarks.hosts.runs import argv_of, descendants, node_name, scene_with
from polymatch_ros.core.saved import load_saved
from polymatch_ros.core.scenes.scene import load_scene
from polymatch_ros.core.stepping.simulate import simulate

pytestmark = needs_ros


# Simulated seconds of the flooded run: each agent matches the rogue's writer on its own
# (measured: up to about a run of t_end 1 after the first agent), and in runs of t_end 1 one
# agent now and then had not matched it before the end, so it had nothing to drop.
ROGUE_T_END = 4.0
ROGUE_AGENTS = 4
RUN_ID = "31337"
ROGUE = os.path.join(REPO, "test", "support", "rogue_publisher.py")
# the foreign states' stamp: late in the realtime run (its t_end is one more), so that a reader
# that took them would take them as agent 3's newest
FOREIGN_STAMP = 299


def test_rogue_publisher_changes_nothing_and_drops_are_counted(ros, tmp_path):
    # the rogue outlives the longest run this test allows (30 s to start flooding + the run's
    # 150 s): it is still sending when the run ends, and the harness ends it by its PID
    rogue = ros.start([PY, ROGUE, "polymatch", "3", "200", "--run-id", RUN_ID], timeout=210)
    deadline = time.monotonic() + 30                  # the flood is on before the run starts
    while "rogue: flooding" not in ros.output(rogue) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert "rogue: flooding" in ros.output(rogue), ros.output(rogue)
    out = tmp_path / "final.npz"
    # four agents, a process each (the scene's triangles): each reads agent 3's stage topic
    scene_file = scene_with(tmp_path, scene_path("congruent_triangles"), ROGUE_AGENTS)
    proc = ros.start(
        cli_argv("run", scene_file, "--t-end", ROGUE_T_END,
                 "--run-id", RUN_ID,  # the rogue's NaN messages carry it: checked, not trusted
                 "--integrator", "rkmk4", "--no-compare", "--save", out, "--timeout", 150, "-q",
                 "--round-timeout", 60,  # the flood is under test, not the timeout
                 "-k", 1),  # a process per agent: each one reads agent 3's stage topic
        timeout=180,
    )
    t0 = time.monotonic()
    rc = ros.wait(proc, 190)
    text = ros.output(proc)
    assert rc in (0, 3), text
    took = time.monotonic() - t0
    assert rogue.poll() is None, (
        f"the rogue must still be sending when the run ends (the run took {took:.0f} s)\n"
        + text + "\n" + ros.output(rogue)
    )
    scene = load_scene(scene_file)
    data = load_saved(out).groups[0]
    traj = simulate(replace(scene, t_end=ROGUE_T_END), "rkmk4", 0.05, samples=[ROGUE_T_END],
                    metrics=False)
    want = scene.model.rotations.to_matrices(traj.final.groups[0].rot)
    assert np.max(np.abs(data.rotations[-1] - want)) <= 1e-12
    assert (
        np.max(np.abs(data.centroids[-1] - (traj.final.groups[0].x + scene.origin))) <= 1e-12
    )
    # every agent of the group listens to agent 3's stages: each dropped the rogue's
    drops = re.findall(r"^agent (\d+): finished.*; dropped (\d+) messages \((.*)\)$", text, re.M)
    assert len(drops) >= ROGUE_AGENTS - 1, text
    reasons = " ".join(d[2] for d in drops)
    assert "non-finite value" in reasons and "unknown sender (run id)" in reasons
    # the monitor reads the run's exchange (the rogue's poses do not reach it), where it
    # dropped the rogue's NaN states and another run's
    mon = re.search(r"^monitor: .*dropped (\d+) messages \((.*)\)$", text, re.M)
    assert (
        mon
        and "unknown sender (run id)" in mon.group(2)
        and "non-finite value" in mon.group(2)
    ), text


def test_foreign_well_formed_states_are_not_read_in_a_realtime_run_theorem_4_2(ros, tmp_path):
    """Another writer sends well-formed states of agent 3, far away and stamped late in the
    run (newer than any real pose), on agent_3/pose and on agent_3/exchange with another run's
    id.  The agents and the monitor read only their run's exchange: the ensemble converges
    (Theorem 4.2) as without the writer, and agent 3's peers count the foreign states as
    another run's.  Read, they would hold agent 3 at (50, 0) in its peers' sums.  The writer
    also sends that run's monitor record (matched, every agent heard): the runner reads only
    this run's records, so it neither stops the run early nor reports the other's diameter."""
    rogue = ros.start([PY, ROGUE, "polymatch", "3", "200", str(FOREIGN_STAMP)], timeout=210)
    deadline = time.monotonic() + 30
    while "rogue: flooding" not in ros.output(rogue) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert "rogue: flooding" in ros.output(rogue), ros.output(rogue)
    scene_file = scene_with(tmp_path, scene_path("congruent_triangles"), ROGUE_AGENTS)
    proc = ros.start(cli_argv("run", scene_file, "--mode", "realtime",
                              "--rate", "20", "--time-scale", "4", "--t-end", FOREIGN_STAMP + 1,
                              "-k", 1, "--timeout", 150), timeout=180)
    rc = ros.wait(proc, 190)
    text = ros.output(proc)
    assert rc == 0 and "converged" in text, text[-3000:]
    # it stopped on convergence, long before the foreign stamp (a run that read the foreign
    # states, tried by accepting any run id, went on to t_end)
    (t_final,) = re.findall(r"^t = (\S+), wall time", text, re.M)
    assert float(t_final) < FOREIGN_STAMP / 2, text[-3000:]
    assert rogue.poll() is None, "the rogue must still be sending when the run ends"
    # -k 1: every other agent reads agent 3's exchange, where the foreign states are (a packed
    # process reads its peers' blocks: states/block_<b>)
    peers = re.search(r"^agent 2: finished.*; dropped \d+ messages \((.*)\)$", text, re.M)
    assert peers and "unknown sender (run id)" in peers.group(1), text[-3000:]
    mon = re.search(r"^monitor: .*dropped (\d+) messages \((.*)\)$", text, re.M)
    assert mon and "unknown sender (run id)" in mon.group(2), text[-3000:]
    ignored = re.search(r"^runner: ignored (\d+) status message\(s\) not of this run$", text,
                        re.M)
    assert ignored and int(ignored.group(1)) > 0, text[-3000:]


def _refused(ros, argv, tmp_path):
    """Start ``argv``: it must exit with code 2 and one line (no traceback), and leave none of
    Fast DDS's files in /dev/shm (its own /dev/shm where it can have one: the process refused
    after its DDS participant was made); that line."""
    listing = tmp_path / "shm_left.txt"
    if private_shm_possible():
        argv = private_shm_argv(argv, listing)
    proc = ros.start(argv, timeout=60)
    assert ros.wait(proc, 70) == 2
    text = ros.output(proc).strip()
    assert len(text.splitlines()) == 1 and "Traceback" not in text, text
    if private_shm_possible():
        assert fast_dds_names(listing) == [], text
    return text


@pytest.mark.parametrize(
    "node,params,expect",
    [
        ("nodes.agent", {"agent": 99}, "agent 99 is not in the scene"),
        ("nodes.agent", {"mode": "fast"}, "expected lockstep or realtime"),
        ("nodes.agent", {"dt": "abc"}, "expected a number"),
        ("nodes.agent", {"rate": -5.0}, "out of range"),
        ("nodes.agent", {"integrator": "rk45"}, "unknown integrator"),
        ("nodes.monitor", {"rate": -1.0}, "out of range"),
        ("nodes.monitor", {"markers": "maybe"}, "expected a boolean"),
    ],
)
def test_bad_node_parameter_is_one_line_and_exit_code_2(ros, node, params, expect, tmp_path):
    text = _refused(ros, node_argv(node, "congruent_triangles", **params), tmp_path)
    assert expect in text, text


def test_missing_scene_is_one_line_and_exit_code_2(ros, tmp_path):
    argv = [PY, "-m", "polymatch_ros.ros.nodes.monitor", "--ros-args", "-p",
            "scene:=/nonexistent.yaml"]
    assert "no such scene file" in _refused(ros, argv, tmp_path)


def _scene_file(path, group, shape, count, dimension, dt, t_end, **extra):
    """A one-group first-order rkmk4 scene, written to ``path`` (YAML)."""
    spec = {"name": path.stem, "dimension": dimension, **extra, "model": {"order": 1},
            "integrator": {"method": "rkmk4", "dt": dt}, "time": {"t_end": t_end},
            "groups": [{"name": group, "shape": shape, "count": count}]}
    path.write_text(yaml.safe_dump(spec, sort_keys=False), encoding="utf-8")
    return path


@pytest.fixture
def colcon_install():
    """The repository's two packages built by colcon (scripts/build-colcon.sh: the set-up's
    workspace build/colcon, built again here, so only what changed since is rebuilt); its install
    base.  A fixture the test requests before ``ros``: the build starts no ROS process, so it
    runs before the test takes a ROS slot, and the slot is held only while the executables run."""
    if not os.path.exists(os.path.join(os.path.dirname(PY), "colcon")):
        pytest.skip("colcon is not installed in this environment")
    build = subprocess.run(["timeout", "-k", "5", "960", "bash",
                            os.path.join(REPO, "scripts", "build-colcon.sh")],
                           capture_output=True, text=True)
    assert build.returncode == 0, build.stdout[-3000:] + build.stderr[-3000:]
    return pathlib.Path(REPO) / "build" / "colcon" / "install"


# ``colcon_install`` before ``ros``: pytest sets up a test's fixtures of one scope in the order
# the test names them, so the build is done before the slot is taken
def test_colcon_build_and_installed_executables_start(colcon_install, ros, tmp_path):
    """colcon builds both packages of the repository, the interface package (ament_cmake,
    rosidl) against the PyPI wheels as scripts/build-interfaces.sh does, and the node
    executables it installs start."""
    interfaces = colcon_install / "polymatch_interfaces"
    assert (interfaces / "share" / "polymatch_interfaces" / "msg" / "AgentState.msg").exists()
    assert (interfaces / "lib" / "python3.11" / "site-packages" / "polymatch_interfaces" / "msg"
            / "_agent_state.py").exists()
    prefix = colcon_install / "polymatch_ros"
    exe = prefix / "lib" / "polymatch_ros"
    assert all((exe / name).exists() for name in ("agent", "monitor", "robot", "polymatch"))
    assert (prefix / "share" / "polymatch_ros" / "config" / "congruent_triangles.yaml").exists()
    site = prefix / "lib" / "python3.11" / "site-packages"
    # the agents import the colcon-built interfaces first (their libraries beside them)
    iface_site = interfaces / "lib" / "python3.11" / "site-packages"
    ros.env["PYTHONPATH"] = f"{site}:{iface_site}"
    ros.env["LD_LIBRARY_PATH"] = f"{interfaces / 'lib'}:{ros.env.get('LD_LIBRARY_PATH', '')}"
    ros.env["AMENT_PREFIX_PATH"] = f"{prefix}:{ros.env.get('AMENT_PREFIX_PATH', '')}"
    scene = _scene_file(tmp_path / "one_agent.yaml", "solo", "tetrahedron", 1, 3, 0.1, 2.0)
    agent = ros.start(
        [str(exe / "agent"), "--ros-args", "-p", f"scene:={scene}", "-p", "agent:=0"], timeout=60
    )
    assert ros.wait(agent, 70) == 0, ros.output(agent)
    assert "agent 0: finished at t = 2 after 20 steps" in ros.output(agent)
    # a shipped scene by name, found in the share directory of the colcon install's prefix
    monitor = ros.start(
        [str(exe / "monitor"), "--ros-args", "-p", "scene:=congruent_triangles"], timeout=60
    )
    # Ctrl-C only once it runs ROS (rclpy.init loads the RMW, then takes SIGINT): before, the
    # interpreter is still importing (seconds on a loaded machine) and a SIGINT is its own
    assert _wait_for_rmw(monitor.pid, 45), ros.output(monitor)
    time.sleep(4.0)
    assert monitor.poll() is None, ros.output(monitor)
    ros.kill(monitor, signal.SIGINT)
    assert ros.wait(monitor, 20) == 0, ros.output(monitor)


def _wait_for_rmw(pid, timeout):
    """True once a process below ``pid`` has loaded Fast DDS's RMW library (rclpy.init)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for child in descendants(pid):
            try:
                with open(f"/proc/{child}/maps") as fh:
                    if "librmw_fastrtps" in fh.read():
                        return True
            except OSError:
                pass
        time.sleep(0.2)
    return False


def _alive(pid):
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().split()[2] != "Z"
    except OSError:
        return False


@pytest.mark.parametrize("how", ["ctrl-c", "child-dies"])
def test_runner_ends_every_process_it_started(ros, tmp_path, how):
    """`polymatch run` ends all its processes by PID on Ctrl-C and, under ``--on-failure
    stop``, when a child dies (four agents, a process each: what counts is that every process
    of each kind ends)."""
    policy = ["--on-failure", "stop"] if how == "child-dies" else []  # restarts: test_faults
    scene = scene_with(tmp_path, scene_path("congruent_triangles"), 4)
    proc = ros.start(
        cli_argv("run", scene, "--t-end", 500, "--timeout", 120, "-k", 1, *policy),
        timeout=150,
    )
    deadline = time.monotonic() + 60
    kids = []
    while time.monotonic() < deadline:
        kids = [p for p in descendants(proc.pid) if _alive(p)]
        if (
            len(kids) >= 6
            and "rounds/s" in ros.output(proc)
            and "t =    0.000" not in ros.output(proc)[-200:]
        ):
            break
        time.sleep(0.5)
    assert len(kids) >= 6, ros.output(proc)  # runner + monitor + 4 agents (+ wrappers)
    runner = _children(proc.pid)[0]
    if how == "ctrl-c":
        os.kill(runner, signal.SIGINT)
        expect_code, expect_text = 130, "interrupted"
    else:
        agent = [p for p in descendants(runner) if node_name(argv_of(p)) == "agent_3"][0]
        os.kill(agent, signal.SIGKILL)
        expect_code, expect_text = 1, "agent_3"
    assert ros.wait(proc, 40) == expect_code, ros.output(proc)
    assert expect_text in ros.output(proc)
    time.sleep(0.5)
    assert not [p for p in kids if _alive(p)], "a process outlived the runner"


def _three_agents_running(ros, tmp_path, t_end, round_timeout):
    """Three lockstep agents, returned once each is well into its rounds (diagnostics show
    t > 0.5): a fixed sleep could strike during discovery on a loaded machine, where the first
    rounds also allow discovery_timeout."""
    scene = _scene_file(
        tmp_path / "three.yaml", "triangles", "triangle", 3, 2, 0.01, t_end, seed=3
    )
    agents = [
        ros.agent(str(scene), i, timeout=90, round_timeout=round_timeout, discovery_timeout=20.0)
        for i in range(3)
    ]
    diag = ros.start(cli_argv("echo", "/diagnostics", "--timeout", 80), timeout=90)
    assert _wait_until_all_step(ros, diag, agents, 3, t_min=0.5, timeout=40), ros.output(diag)[
        -2000:
    ]
    assert all(a.poll() is None for a in agents), [ros.output(a) for a in agents]
    return agents


def test_vanished_peer_makes_neighbours_round_time_out_naming_it(ros, tmp_path):
    """Lockstep: SIGKILL one agent mid-run; its neighbours stop with a one-line error naming it
    as gone (its writer unmatched once its DDS lease ran out)."""
    agents = _three_agents_running(ros, tmp_path, 1000.0, round_timeout=2.0)  # ~1e5 steps
    ros.kill(agents[2])
    for a in agents[:2]:
        assert ros.wait(a, 30) == 1, ros.output(a)
        text = ros.output(a)
        errors = [line for line in text.splitlines() if line.startswith("agent: error:")]
        assert len(errors) == 1 and "timed out after 2 s waiting for agent(s) " in errors[0], text
        # the vanished agent is named; the other survivor may be named too: when the victim's
        # last message reached one survivor and not the other (a SIGKILLed writer repairs
        # nothing), that survivor is a round behind and both time out, each naming the other
        named = re.search(r"waiting for agent\(s\) ([0-9, ]+)", errors[0]).group(1)
        others = {int(k) for k in named.split(",")}
        assert 2 in others and others <= {0, 1, 2} - {agents.index(a)}, errors[0]
        gone = re.search(r"; agent\(s\) ([0-9, ]+) left", errors[0])
        assert gone is not None and gone.group(1).strip(), errors[0]
        assert "Traceback" not in text


def test_a_stalled_peer_is_waited_for_and_the_run_completes(ros, tmp_path):
    """Lockstep: one agent is frozen (SIGSTOP) for 4 s, four times round_timeout, as a loaded
    machine can starve a process.  Its writer stays matched (the DDS lease is 10 s), so its
    neighbours wait instead of failing, and all three finish the run.  (With stall_timeout
    below the freeze the same run fails naming agent 2 "present but silent".)"""
    agents = _three_agents_running(ros, tmp_path, 5.0, round_timeout=1.0)   # 500 steps
    frozen = _children(agents[2].pid)
    assert frozen
    for pid in frozen:
        os.kill(pid, signal.SIGSTOP)
    try:
        time.sleep(4.0)
        assert all(a.poll() is None for a in agents), [ros.output(a)[-600:] for a in agents]
    finally:
        for pid in frozen:
            os.kill(pid, signal.SIGCONT)
    for a in agents:
        assert ros.wait(a, 60) == 0, ros.output(a)[-1500:]
        assert "finished at t = 5" in ros.output(a), ros.output(a)[-1500:]


def _wait_until_all_step(ros, diag, agents, n, t_min, timeout):
    """True once each of agents 0..n-1 has reported (diagnostics) a simulated time above t_min."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        reached = {
            int(a)
            for a, t in re.findall(
                r"agent_(\d+)\s*\n\s*message: lockstep: t = ([0-9.e+-]+)", ros.output(diag)
            )
            if float(t) > t_min
        }
        if reached >= set(range(n)):
            return True
        if any(a.poll() is not None for a in agents):
            return False
        time.sleep(0.2)
    return False
