"""The monitor's certificate topic: granted once the state enters Theorem 4.2's region, latched."""

import math
import re
from itertools import combinations

import numpy as np
import pytest
import yaml
from ros_harness import cli_argv, needs_ros, node_argv
from scipy.optimize import brentq

from polymatch_ros.core import load_scene, simulate

pytestmark = needs_ros

# 3-D, three tetrahedra with Haar-uniform rotations: D0 = 2.53 >= 1 at t = 0 (not certified),
# below 1 from t = 1.6 on (the centralised run): the monitor grants the certificate mid-run
SCENE = {"name": "certificate_run", "dimension": 3, "seed": 6,
         "model": {"order": 1, "kappa": 1.0, "gamma": 1.0},
         "integrator": {"method": "rkmk4", "dt": 0.1}, "time": {"t_end": 2.0},
         "groups": [{"name": "g", "shape": "tetrahedron", "count": 3,
                     "centroids": {"box": [-1.0, 1.0]}, "rotations": "uniform"}]}
N = 3


def _values(text):
    """{key: value} of the last DiagnosticStatus `polymatch echo` printed."""
    block = text[text.rindex("level:"):]
    return dict(re.findall(r"- key: (\S+)\n\s+value: ?(.*)", block))


def _diameter(points):
    """max |p_i - p_j| over pairs, brute force."""
    return max(float(np.linalg.norm(p - q)) for p, q in combinations(points, 2))


def _theorem_4_2_time(scene, state):
    """When Thm 4.2's bound from ``state`` falls below the tolerance, written out: with
    c = kappa/gamma, D_x the centroids' and D_O the rotations' diameter (Frobenius, < 1), R the
    largest vertex radius, D_x e^{-c tau} + R/sqrt 2 D_O e^{-c tau}/(1 - D_O + D_O e^{-c tau})
    = tolerance (decreasing in tau: brentq); None where D_O >= 1 (no guarantee)."""
    model, gs = scene.model, state.groups[0]
    mats = model.rotations.to_matrices(gs.rot).reshape(len(gs.x), -1)
    d_x, d_o = _diameter(gs.x), _diameter(mats)
    if d_o >= 1.0:
        return None
    radius = float(np.linalg.norm(model.groups[0].reference, axis=1).max())
    c = model.kappa / model.gamma

    def excess(tau):
        e = math.exp(-c * tau)
        return d_x * e + radius / math.sqrt(2) * d_o * e / (1 - d_o + d_o * e) - scene.tolerance

    return brentq(excess, 0.0, 1e3, xtol=1e-12, rtol=1e-14)


def test_monitor_grants_certificate_mid_run_and_a_late_echo_gets_it_thm_4_2(ros, tmp_path):
    path = tmp_path / "certificate_run.yaml"
    path.write_text(yaml.safe_dump(SCENE))
    scene = load_scene(str(path))
    assert _theorem_4_2_time(scene, scene.initial) is None       # D_O >= 1 at t = 0
    ros.monitor(str(path), timeout=120, agents_per_process=N)  # the agents send one block
    # one process hosts the three agents (as `polymatch run -k 3` does): fewer starts
    agents = ros.start(node_argv("nodes.agent", str(path), agents=list(range(N)),
                                 agents_per_process=N, exchange_subscribers=1)
                       + ["-r", f"__node:=agents_0_{N - 1}"], 90, "agents")
    assert ros.wait(agents, 100) == 0, ros.output(agents)[-2000:]
    # the run is over, the monitor still serves its latched certificate to a late reader
    echo = ros.start(cli_argv("echo", "/polymatch/certificate", "--count", 1, "--timeout", 30),
                     timeout=40)
    assert ros.wait(echo, 45) == 0, ros.output(echo)
    text = ros.output(echo)
    assert re.search(r"^level: (\[0\]|0)$", text, re.M), text          # OK: granted
    values = _values(text)
    assert values["certified"] == "true" and values["theorem"].startswith("Thm 4.2"), values
    issued, guaranteed = float(values["issued_at"]), float(values["guaranteed_time"])
    assert 1.5 <= issued <= 2.0, values              # granted once D_O < 1, not at t = 0
    # Thm 4.2's time from the centralised run's state at that time (its step), written out
    traj = simulate(scene, samples=[issued])
    at = [k for k, t in enumerate(traj.times) if abs(t - issued) < 1e-9]
    assert len(at) == 1, (traj.times, issued)                  # a step the run reported
    tau = _theorem_4_2_time(scene, traj.states[at[0]])
    assert tau is not None and guaranteed == pytest.approx(issued + tau, rel=1e-6)
    m = re.search(r"^message: certified: matching diameter < 1e-06 by t <= (\S+) \(Thm 4\.2",
                  text, re.M)
    assert m and guaranteed <= float(m.group(1)) <= guaranteed * (1 + 1e-2), text  # rounded up
    assert np.isfinite(guaranteed) and guaranteed > issued
