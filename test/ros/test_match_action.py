"""The ``/polymatch/match`` action: a goal from an rclpy ActionClient (test/support/match_probe.py,
a process of its own beside `polymatch run`) gets feedback at the monitor's reports and a result;
cancelling it stops the ensemble as ``/polymatch/stop`` does.

Oracle: the result's diameter against the matching diameter max_{i,j,a} |x^i_a - x^j_a| computed
here by brute force over every pair of agents and every vertex, from the agents' own pose
topics at the simulated time of the result (rotations from the quaternions by scipy).
"""

import itertools
import json
import os

import numpy as np
from ros_harness import PY, REPO, cli_argv, needs_ros, scene_path
from scipy.spatial.transform import Rotation

from polymatch_ros.core.scenes.scene import load_scene

pytestmark = needs_ros

PROBE = os.path.join(REPO, "test", "support", "match_probe.py")
SCENE = "congruent_triangles"
N = 8
STATUS_SUCCEEDED, STATUS_CANCELED = 4, 5  # action_msgs/GoalStatus


def probe_lines(ros, proc):
    return [json.loads(line) for line in ros.output(proc).splitlines() if line.startswith("{")]


def brute_force_diameter(poses, reference):
    """max over agent pairs (i, j) and vertices a of |x^i_a - x^j_a|, each vertex placed as
    position + R(quaternion) r_a."""
    placed = []
    for x, y, _z, qx, qy, qz, qw in poses.values():
        rot = Rotation.from_quat([qx, qy, qz, qw]).as_matrix()[:2, :2]
        placed.append(np.array([x, y]) + reference @ rot.T)
    return max(
        float(np.linalg.norm(vi[a] - vj[a]))
        for vi, vj in itertools.combinations(placed, 2) for a in range(len(reference))
    )


def run_with_probe(ros, run_args, probe_args):
    run = ros.start(cli_argv("run", scene_path(SCENE), "-k", 4, "--timeout", 200, *run_args),
                    timeout=230, name="run")
    probe = ros.start([PY, PROBE, "--agents", N, *probe_args], timeout=220, name="probe")
    return run, probe


def test_match_goal_gets_feedback_and_matched_result_theorem_4_2(ros):
    """Theorem 4.2 (congruent polytopes, first-order model): the diameter goes to 0, so a goal at
    the scene's tolerance (1e-6) ends matched; the feedback shows the diameter falling from
    its initial spread, every agent heard; the result's diameter is the brute-force diameter of
    the poses at its time."""
    run, probe = run_with_probe(ros, [], [])
    assert ros.wait(probe, 220) == 0, ros.output(probe)[-3000:] + ros.output(run)[-3000:]
    assert ros.wait(run, 60) == 0, ros.output(run)
    lines = probe_lines(ros, probe)
    feedback = [line["feedback"] for line in lines if "feedback" in line]
    (done,) = [line for line in lines if "result" in line]
    (poses,) = [line for line in lines if "poses" in line]
    result = done["result"]
    assert done["status"] == STATUS_SUCCEEDED and result["matched"], done
    assert result["reason"] == "matched"
    assert len(feedback) >= 2 and all(f["n_agents"] == N for f in feedback)
    ts = [f["t"] for f in feedback]
    assert ts == sorted(ts)
    assert feedback[0]["diameter"] > 1.0 and feedback[-1]["agents_heard"] == N
    assert all(f["certificate"] in ("granted", "refused", "pending") for f in feedback)
    assert result["matched_at"] == poses["t"] == ts[-1]
    assert result["diameter"] < 1e-6
    reference = load_scene(scene_path(SCENE)).model.groups[0].reference
    assert len(poses["poses"]) == N
    oracle = brute_force_diameter(poses["poses"], reference)
    assert abs(result["diameter"] - oracle) <= 1e-12, (result, oracle)


def test_cancelled_match_goal_stops_the_run_exit_4(ros):
    """Cancelling a goal stops the ensemble (the stop service's broadcast): the run ends before
    it matches, as stopped by request (exit 4), and the result is the canceled goal's, with the
    diameter of the last report (brute force from the poses of that time)."""
    run, probe = run_with_probe(ros, ["--dt", 0.01], ["--tolerance", 1e-9, "--cancel-after", 3])
    assert ros.wait(probe, 220) == 0, ros.output(probe)[-3000:] + ros.output(run)[-3000:]
    assert ros.wait(run, 60) == 4, ros.output(run)
    assert "stopped by request" in ros.output(run)
    lines = probe_lines(ros, probe)
    assert {"cancel": 1} in lines
    (done,) = [line for line in lines if "result" in line]
    (poses,) = [line for line in lines if "poses" in line]
    result = done["result"]
    assert done["status"] == STATUS_CANCELED, done
    assert not result["matched"] and result["reason"] == "canceled"
    assert result["matched_at"] is None
    assert result["diameter"] > 1e-6  # stopped before it matched
    reference = load_scene(scene_path(SCENE)).model.groups[0].reference
    oracle = brute_force_diameter(poses["poses"], reference)
    assert abs(result["diameter"] - oracle) <= 1e-12 * max(1.0, oracle), (result, oracle)
