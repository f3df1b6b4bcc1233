"""/clock in lockstep: a plain rclpy reader started with ``use_sim_time`` (test/support/
clock_probe.py) sees the clock advance and its own clock follow it, and every time the clock
shows is a step of the scene's grid t = k dt and the stamp of that step's poses.  The clock
keeps its pace while the run goes on (``report_rate``, 20 a second by default): never still for
a second and a half, whatever the diameter reports cost."""

import os
import re

import numpy as np
from core_testlib import triangles_yaml
from ros_harness import PY, cli_argv, needs_ros

pytestmark = needs_ros

# 2000 lockstep steps, a process per agent (-k 1): the agents start stepping only once they
# have discovered each other, which the probe, started first, does meanwhile, so that its readers
# match while the run goes on (the agents publish poses only to matched readers, and a reader
# matched after the last step would hear nothing).  One process stepping all three agents
# needs no discovery before its first step, and twice ended its run before the probe's pose
# reader had matched.
DT, T_END = 0.01, 20.0
SCENE = triangles_yaml("three_triangles", seed=5, count=3, method="lie_euler", dt=DT,
                       t_end=T_END, snapshots=[0])
# the longest a reader of /clock may see it hold while the run goes on (wall-clock s)
MOST_STILL = 1.5
PROBE = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "support",
                     "clock_probe.py")


def test_clock_follows_the_simulated_time_of_the_poses(ros, tmp_path):
    scene_file = tmp_path / "three.yaml"
    scene_file.write_text(SCENE)
    end_ns = round(T_END * 1e9)
    probe = ros.start([PY, PROBE, "/polymatch/agent_0/pose", str(end_ns), "150"], timeout=160,
                      name="clock probe")
    run = ros.start(cli_argv("run", scene_file, "-k", 1, "--no-compare", "--hold", "1e9",
                             "--timeout", 120), timeout=150)
    assert ros.wait(run, 160) == 0, ros.output(run)  # matched, held to t_end
    assert ros.wait(probe, 60) == 0, ros.output(probe)[-2000:]
    said = ros.output(probe)
    heard = [(int(v), float(w)) for v, w in re.findall(r"^CLOCK (\d+) ([\d.]+)$", said, re.M)]
    clocks, when = [c for c, _ in heard], [w for _, w in heard]
    poses = {int(v) for v in re.findall(r"^POSE (\d+)$", said, re.M)}
    assert len(clocks) >= 3 and poses, said[-1500:] + ros.output(run)
    # it advances regularly: at 20 values a wall-clock second, no gap of 30 of them
    gaps = np.diff(when)
    assert gaps.max() < MOST_STILL, (gaps.max(), clocks, when)
    assert all(a < b for a, b in zip(clocks, clocks[1:])), clocks  # never back, never twice
    for ns in clocks:  # on the grid t = k dt (within a microsecond) ...
        k = round(ns * 1e-9 / DT)
        assert 0 <= k <= round(T_END / DT) and abs(ns - k * DT * 1e9) < 1e3, (ns, k)
        # ... and, once the probe's pose reader matched, exactly a stamp of agent 0's poses
        assert ns < min(poses) or ns in poses, (ns, sorted(poses))
    assert clocks[-1] == end_ns  # the last step is reported, so the clock reaches t_end
    now, active = re.search(r"^NOW (\d+) (\w+)$", said, re.M).groups()
    assert active == "True" and int(now) == end_ns  # the reader's own clock follows /clock
