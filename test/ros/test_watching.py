"""Watching costs next to nothing, and what it shows stays exact: lockstep agents send their
states on the run's exchange at the monitor's pace (``exchange_rate``, ``agents.state_stride``),
at steps that every process sends, and the monitor reports only steps it has from every agent.
So each report is the centralised run's state at one step of the grid (lockstep equals the
centralised run to round-off: the paper's matching diameter as the simulator has it), while a
reader of a block's states hears a few dozen messages a second, not one a step."""

import re

import numpy as np
import pytest
from core_testlib import triangles_yaml
from exactness import central_vertices
from ros_harness import cli_argv, needs_ros, placed_vertices
from scipy.spatial.distance import pdist

from polymatch_ros.core import load_scene
from polymatch_ros.core.stepping.simulate import choose_numerics

pytestmark = needs_ros

DT, T_END, N = 0.0025, 3.0, 8  # 1200 lockstep steps, two processes of four agents
STEPS = round(T_END / DT)
SCENE = triangles_yaml("watched", seed=3, count=N, method="lie_euler", dt=DT, t_end=T_END)
EXCHANGE_RATE = 40.0  # the agents' default: twice the monitor's report rate
REPORT = re.compile(r"- key: t\n\s+value: (\S+)\n\s+- key: diameter\n\s+value: (\S+)")


def _matching_diameter(vertices):
    """max_{i,j,a} |x^i_a - x^j_a|, brute force over the pairs of agents, vertex by vertex."""
    return max(float(pdist(v).max()) for group in vertices for v in group)


def test_monitor_reports_exact_steps_from_states_sent_at_its_pace(ros, tmp_path):
    path = tmp_path / "watched.yaml"
    path.write_text(SCENE)
    diag = ros.start(cli_argv("echo", "/diagnostics", "--timeout", 150), timeout=160,
                     name="diagnostics")
    block = ros.start(cli_argv("echo", "/polymatch/states/block_0", "--timeout", 150),
                      timeout=160, name="block 0")
    run = ros.start(cli_argv("run", path, "-k", 4, "--no-compare", "--timeout", 120),
                    timeout=150)
    assert ros.wait(run, 160) == 3, ros.output(run)[-3000:]  # to t_end, not matched yet
    wall = float(re.search(r"wall time ([0-9.]+) s", ros.output(run)).group(1))
    ros.kill(diag)
    ros.kill(block)
    reports = {float(t): float(d) for t, d in REPORT.findall(ros.output(diag))}
    assert len(reports) >= 2, ros.output(diag)[-2000:]
    scene = load_scene(str(path))
    method = choose_numerics(scene, None, None, distributed=True).name
    for t, diameter in sorted(reports.items()):
        k = round(t / DT)  # a step of the grid t = k dt ...
        assert 0 <= k <= STEPS and abs(t - k * DT) < 1e-9, t
        # ... and the centralised run's diameter at that step, to round-off
        central = central_vertices(scene, method, t) if k else placed_vertices(
            scene.model, scene.initial.groups, scene.origin)
        want = _matching_diameter(central)
        assert diameter == pytest.approx(want, rel=1e-9, abs=1e-12), (t, diameter, want)
    # the block's states came at the monitor's pace, not every step: a message a step would
    # be 1200 of them, whatever the machine's load
    sent = len(re.findall(r"^block: 0$", ros.output(block), re.M))
    assert 1 <= sent <= min(STEPS // 2, 2 * EXCHANGE_RATE * wall + 10), (sent, wall)
    assert np.isfinite(wall)
