"""Multi-process lockstep runs equal the centralised simulator (the same stepper, to round-off).

Each case starts the whole node set with `polymatch run` (monitor + one process per
agent, or per K agents) in the test's own ROS domain, saves the final poses exactly as
they arrived on the pose topics, and compares every vertex with `simulate` computed here.
"""

import re

import numpy as np
import pytest
from exactness import central_vertices, received_vertices
from ros_harness import cli_argv, needs_ros, placed_vertices, scene_path
from shm_watch import ShmWatch

from polymatch_ros.core.metrics import ensemble_metrics
from polymatch_ros.core.model import GroupState, State
from polymatch_ros.core.saved import load_saved
from polymatch_ros.core.scenes.scene import load_scene
from polymatch_ros.ros.wire import run_records

pytestmark = needs_ros

T_END = 1.0

CASES = [
    # scene, integrator (1 stage / 4 stages), agents per process
    ("congruent_triangles", "lie_euler", 1),
    ("congruent_triangles", "rkmk4", 1),
    # a projection method computes with matrices in 2-D, where the monitor and runner keep angles
    ("congruent_triangles", "rk4_proj", 2),
    ("similar_triangles", "lie_euler", 4),
    ("similar_triangles", "rkmk4", 2),
    ("mixed_triangles_tetrahedra", "lie_euler", 4),
    ("mixed_triangles_tetrahedra", "rkmk4", 3),
    ("simplices_4d", "lie_euler", 2),
    ("simplices_4d", "rkmk4", 1),
]


def assert_saved_poses_equal_centralised(scene, integrator, saved, t_end=T_END):
    """The final poses the runner saved are at ``t_end`` (None: wherever the run stopped) and
    equal the centralised run's there to 1e-9 (brute force over agents and vertices); returns
    their vertices."""
    t, got = received_vertices(scene, saved)
    if t_end is not None:
        assert t == pytest.approx(t_end)
    want = central_vertices(scene, integrator, t)
    dev = max(float(np.max(np.linalg.norm(a - b, axis=-1))) for a, b in zip(got, want))
    assert dev <= 1e-9, f"max vertex deviation {dev:.3e}"
    return got


def received_state(scene, path):
    """The final poses saved by the runner as a core State (first-order scenes)."""
    saved, grp = load_saved(path), scene.model.rotations
    groups = tuple(
        GroupState(sg.centroids[-1] - scene.origin, grp.from_matrices(sg.rotations[-1]))
        for sg in saved.groups
    )
    return State(saved.t, groups)


def assert_monitor_reported_final_state(scene, records, saved):
    """The monitor reports at most report_rate times a second, yet its last report is the
    final step's: the diameter of the final poses, at t_end, with every agent heard."""
    (mon,) = [r for r in run_records(records.read_text().splitlines()) if r.role == "monitor"]
    final = received_state(scene, saved)
    assert mon.t == pytest.approx(final.t, abs=1e-9), mon
    assert mon.agents_heard == scene.model.n_agents, mon
    want = ensemble_metrics(scene.model, final).diameter
    assert mon.diameter == pytest.approx(want, rel=1e-9, abs=1e-12), (mon.diameter, want)


@pytest.mark.parametrize("name,integrator,k", CASES)
def test_lockstep_equals_centralised_simulation(ros, tmp_path, name, integrator, k):
    out, records = tmp_path / "final.npz", tmp_path / "records.jsonl"
    proc = ros.start(
        cli_argv("run", scene_path(name), "--integrator", integrator, "--t-end", T_END, "-k", k,
                 "--timeout", 150, "--no-compare", "--save", out, "-q", "--run-records", records),
        timeout=180,
    )
    rc = ros.wait(proc, 190)
    text = ros.output(proc)
    # 3: ran to t_end without converging (t_end is short)
    assert rc in (0, 3), text
    scene = load_scene(scene_path(name))
    got = assert_saved_poses_equal_centralised(scene, integrator, out)
    # the agents really moved: the comparison is not between two copies of the initial state
    initial = placed_vertices(scene.model, scene.initial.groups, scene.origin)
    moved = max(float(np.max(np.linalg.norm(a - b, axis=-1))) for a, b in zip(got, initial))
    assert moved > 0.1
    assert_monitor_reported_final_state(scene, records, out)


def test_packed_blocks_cut_across_two_runners_equal_the_centralised_run(ros, tmp_path):
    """Packed processes send one message per block of K agents and round.  Two runners in one
    domain (two hosts' commands) with --only cutting blocks: 0-2 here, 3-7 there, K = 4, so
    block 0 has writers in both, and one process hosts agents of blocks 0 and 1."""
    out, name, integrator = tmp_path / "final.npz", "congruent_triangles", "rkmk4"
    common = ("--integrator", integrator, "--t-end", T_END, "-k", 4, "--timeout", 150, "-q")
    other = ros.start(cli_argv("run", scene_path(name), "--only", "0-2", "--no-monitor",
                               *common), timeout=180)
    lead = ros.start(cli_argv("run", scene_path(name), "--only", "3-7", "--save", out,
                              *common), timeout=180)
    assert ros.wait(lead, 190) in (0, 3), ros.output(lead)
    assert ros.wait(other, 60) in (0, 3), ros.output(other)
    text = ros.output(lead)
    m = re.search(r"max vertex deviation ([0-9.e+-]+)", text)
    assert m and float(m.group(1)) <= 1e-9, text
    scene = load_scene(scene_path(name))
    assert_saved_poses_equal_centralised(scene, integrator, out)


def test_runner_converges_theorem_4_2_and_echo_sees_diameter_below_tolerance(ros, tmp_path):
    """README's demo: `polymatch run` converges and stops early; a separate subscriber process
    (the launch-free stand-in for `ros2 topic echo /polymatch/diameter`) sees the diameter fall
    below the scene's tolerance; the runner reports the lockstep deviation."""
    echo = ros.start(
        cli_argv("echo", "/polymatch/diameter", "--until-below", "1e-6", "--timeout", 200),
        timeout=220,
    )
    records, saved = tmp_path / "records.jsonl", tmp_path / "final.npz"
    proc = ros.start(
        # two agent processes: each round crosses processes, and fewer processes step faster
        cli_argv("run", scene_path("congruent_triangles"), "-k", 4, "--timeout", 200,
                 "--run-records", records, "--save", saved),
        timeout=230,
    )
    shm = ShmWatch(lambda: [proc.pid])  # the run's processes' /dev/shm entries
    rc = ros.wait(proc, 240)
    shm.stop()
    text = ros.output(proc)
    assert rc == 0, text
    # a clean run leaves /dev/shm as it found it: the Fast DDS segments its runner, monitor and
    # two agent processes made, seen while they ran, are gone
    assert len(shm.segments) >= 3 and shm.left() == [], (shm.seen, shm.left())
    assert ros.wait(echo, 20) == 0, ros.output(echo)
    values = [float(v) for v in re.findall(r"^data: (\S+)$", ros.output(echo), re.M)]
    assert values[0] > 1.0 and values[-1] < 1e-6
    m = re.search(r"max vertex deviation ([0-9.e+-]+)", text)
    assert m and float(m.group(1)) <= 1e-9, text
    assert "converged: matching diameter < 1e-06" in text
    assert "stopped by request" not in text  # the runner's own stop, on convergence
    # the harness reserved the domain for this test: the run says so (and so looked for no
    # other ensemble of its name before it started)
    assert f"ROS graph: domain {ros.domain}, reserved for this run by its caller" in text
    t_final = float(re.search(r"\nt = ([0-9.e+-]+), wall time", text).group(1))
    # a normal run is clean: nothing dropped, by the monitor or any agent
    assert re.search(r"^monitor: last report .*; no messages dropped$", text, re.M), text
    recs = run_records(records.read_text().splitlines())
    assert len(recs) == 3 and all(r.finished for r in recs if r.role == "agent"), recs
    assert all(r.dropped == {} for r in recs), [r.dropped for r in recs]
    assert t_final < load_scene(scene_path("congruent_triangles")).t_end  # stopped on convergence
    scene = load_scene(scene_path("congruent_triangles"))
    assert_saved_poses_equal_centralised(scene, scene.integrator.method, saved, t_end=None)
