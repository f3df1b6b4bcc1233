"""Proximity graphs over ROS (``graph: {radius: R}``): in lockstep every agent hears every peer's
stage messages (any of them may come into range) and weighs them as the centralised run does,
so the run equals `simulate` to 1e-9 while pairs enter the range; realtime agents couple only to
the peers within R of their latest poses, as radios would, and the monitor's diagnostics and
the run's verdict name the components."""

import re

import numpy as np
import pytest
from exactness import central_vertices, received_vertices
from ros_harness import PY, needs_ros, scene_path

from polymatch_ros.core.saved import load_saved
from polymatch_ros.core.scenes.scene import load_scene
from polymatch_ros.ros.wire import run_records

pytestmark = needs_ros


def test_lockstep_on_radio_connected_equals_the_centralised_run_while_pairs_enter_range(
        ros, tmp_path):
    path = scene_path("radio_connected")
    out, records = tmp_path / "final.npz", tmp_path / "records.jsonl"
    proc = ros.start([PY, "-m", "polymatch_ros.cli", "run", path, "--t-end", "1", "-k", "4",
                      "--timeout", "150", "--save", str(out), "--run-records", str(records), "-q"],
                     timeout=180)
    rc = ros.wait(proc, 190)
    text = ros.output(proc)
    assert rc in (0, 3), text
    scene = load_scene(path)
    t, got = received_vertices(scene, out)
    assert t == pytest.approx(1.0)
    want = central_vertices(scene, "rkmk4", t)
    dev = max(float(np.max(np.linalg.norm(a - b, axis=-1))) for a, b in zip(got, want))
    assert dev <= 1e-9, f"max vertex deviation {dev:.3e}"
    m = re.search(r"max vertex deviation ([0-9.e+-]+)", text)   # the runner's own comparison
    assert m and float(m.group(1)) <= 1e-9, text
    centroids = load_saved(out).groups[0].centroids[-1]               # 19 pairs in range at t = 0
    r = np.linalg.norm(centroids[:, None] - centroids[None], axis=-1)
    assert int(np.sum(np.triu(r < 5.0, 1))) == 28, r              # all 28 by t = 1
    agents = [r for r in run_records(records.read_text().splitlines()) if r.role == "agent"]
    assert len(agents) == 2 and all(r.finished for r in agents), agents
    for rec in agents:                                           # every peer's stage messages
        assert sorted(rec.peers) == sorted(set(range(8)) - set(rec.agents)), rec


RADIO = """\
name: radio_pair_and_loner
dimension: 2
seed: 2
model: {order: 1, kappa: 2.0, gamma: 1.0}
graph: {radius: 3.0, allow_disconnected: true}
integrator: {method: rkmk4, dt: 0.1}
time: {t_end: 6.0}
convergence: {tolerance: 1.0e-6, expected: true}
groups:
  - {name: g, shape: triangle, count: 3, centroids: {points: [[0, 0], [1.5, 0], [10, 0]]},
     rotations: {angles: [0.0, 1.0, 2.0]}}
"""


def test_realtime_agents_couple_only_to_peers_in_range_and_the_split_is_named(ros, tmp_path):
    """Agents 0 and 1 are 1.5 apart, agent 2 is 8.5 from both, radius 3: agent 2 hears nobody
    and never moves (its pose stays the initial one), 0 and 1 couple; the monitor's diagnostics
    show the components {0, 1} {2}, each agent's the peers in range, and the run exits 3."""
    path = tmp_path / "radio.yaml"
    path.write_text(RADIO)
    out = tmp_path / "final.npz"
    echo = ros.start([PY, "-m", "polymatch_ros.cli", "echo", "/diagnostics", "--timeout", "90"],
                     timeout=100)
    # -k 1: a process per agent, each one's diagnostics name its peers in range
    proc = ros.start([PY, "-m", "polymatch_ros.cli", "run", str(path), "--mode", "realtime",
                      "--rate", "20", "--time-scale", "2", "--timeout", "90", "--save", str(out),
                      "-k", "1", "-q"], timeout=120)
    rc = ros.wait(proc, 130)
    text = ros.output(proc)
    assert rc == 3, text
    assert "group 'g' split into 2 components {0, 1} {2} (radius 3) at t = 6" in text, text
    data = load_saved(out).groups[0]
    x, mats = data.centroids[-1], data.rotations[-1]
    theta = np.arctan2(mats[:, 1, 0], mats[:, 0, 0])
    assert np.max(np.abs(x[2] - [10.0, 0.0])) < 1e-12 and abs(theta[2] - 2.0) < 1e-12
    assert abs(theta[1] - theta[0]) < 0.5 and np.linalg.norm(x[1] - x[0]) < 1.0   # 0, 1 met
    ros.kill(echo)
    diag = ros.output(echo)
    assert "split into 2 components {0, 1} {2} (radius 3)" in diag, diag[-3000:]
    heard = [int(v) for v in re.findall(r"key: peers_in_range\s+value: '?(\d+)", diag)]
    assert heard and set(heard) <= {0, 1} and 0 in heard and 1 in heard, diag[-3000:]
