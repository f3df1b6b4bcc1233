"""`polymatch trade`: the recommended setting reaches the target error, checked against an
independent solve of the paper's (A-2) with scipy; the flattened model scipy integrates is
(A-1)/(A-2); the budget is honoured; bad input and an unreachable target exit as documented."""

import json
import time

import numpy as np
import pytest
import yaml
from core_testlib import rot_matrices, skew_matrices, triangles_yaml
from scipy.integrate import solve_ivp

from polymatch_ros.cli import main
from polymatch_ros.core import load_scene, simulate
from polymatch_ros.core.stepping.flat import FlatModel
from polymatch_ros.core.trade import trade

TRIANGLES = triangles_yaml("four_triangles", seed=5, count=4, method="rkmk4", dt=0.05, t_end=4.0,
                           gamma=2.0)


# The command-line runs' horizons (s): their whole grid of 46 runs fits within the budgets they
# give (over t_end = 4 s the grid outgrew them and took the budget).
RECOMMEND_T_END = 1.0     # six sample times; the choice's error is ~6e-8 (rkmk4 dt 0.2)
UNREACHABLE_T_END = 0.4   # the smallest error of the grid is 1.6e-13, far above 1e-16


@pytest.fixture
def triangles(tmp_path):
    path = tmp_path / "four_triangles.yaml"
    path.write_text(TRIANGLES)
    return str(path)


@pytest.fixture
def triangles_until(tmp_path):
    """A function writing TRIANGLES over the horizon ``t_end`` to a file: its path."""
    def write(t_end):
        spec = yaml.safe_load(TRIANGLES)
        spec["time"]["t_end"] = t_end
        path = tmp_path / f"four_triangles_{t_end:g}.yaml"
        path.write_text(yaml.safe_dump(spec))
        return str(path)
    return write


def paper_a2(kappa, gamma, n, d):
    """(A-2) written from the paper with the double sum over k (no mean field):
    x_i' = kappa/(gamma N) sum_k (x_k - x_i),
    O_i' = kappa/(2 gamma N) sum_k (O_k O_i^T - O_i O_k^T) O_i."""
    def rhs(t, y):
        x = y[:n * d].reshape(n, d)
        o = y[n * d:].reshape(n, d, d)
        dx = np.zeros_like(x)
        do = np.zeros_like(o)
        for i in range(n):
            w = np.zeros((d, d))
            for k in range(n):
                dx[i] += kappa / (gamma * n) * (x[k] - x[i])
                w += o[k] @ o[i].T - o[i] @ o[k].T
            do[i] = kappa / (2 * gamma * n) * w @ o[i]
        return np.concatenate([dx.ravel(), do.ravel()])
    return rhs


def oracle_vertices(scene, times):
    """Every vertex x_i + O_i r_a at ``times`` from scipy's DOP853 at rtol = atol = 1e-12 on
    ``paper_a2`` (one congruent group)."""
    m, gs = scene.model, scene.initial.groups[0]
    n, d = m.n_agents, m.dim
    y0 = np.concatenate([gs.x.ravel(), rot_matrices(m.rotations, gs.rot).ravel()])
    sol = solve_ivp(paper_a2(m.kappa, m.gamma, n, d), (0.0, scene.t_end), y0,
                    method="DOP853", rtol=1e-12, atol=1e-12, t_eval=times)
    x = sol.y[:n * d].T.reshape(-1, n, 1, d)
    o = sol.y[n * d:].T.reshape(-1, n, d, d)
    return x + np.einsum("tnij,aj->tnai", o, m.groups[0].reference)


def vertices_of(scene, states):
    rep, ref = scene.model.rotations, scene.model.groups[0].reference
    x = np.array([st.groups[0].x for st in states])[:, :, None, :]
    o = np.array([rot_matrices(rep, st.groups[0].rot) for st in states])
    return x + np.einsum("tnij,aj->tnai", o, ref)


def test_recommended_setting_reaches_the_target_error_against_scipy_on_paper_a2(triangles_until,
                                                                                 capsys):
    """The JSON's choice, run as a user would (`simulate` with its scene keys), is within the
    target of an independent tight solve of (A-2) at every sample time, and its error is the
    one the table reports; the keys are valid scene YAML."""
    target = 1e-6
    path = triangles_until(RECOMMEND_T_END)
    code = main(["trade", path, "--target-error", str(target), "--budget", "3", "--json"])
    data = json.loads(capsys.readouterr().out)
    assert code == 0 and data["exit_code"] == 0
    choice = data["choice"]
    keys = yaml.safe_load(choice["scene_keys"])["integrator"]
    with open(path) as fh:
        spec = yaml.safe_load(fh)
    spec["integrator"] = keys
    scene = load_scene(spec)
    times = np.linspace(0.0, scene.t_end, 6)                # every 0.2: on every step
    assert data["samples"] == len(times)                    # the table's errors are taken there
    traj = simulate(scene, samples=times, metrics=False)
    assert traj.numerics.name == choice["solver"]
    assert np.allclose(traj.times, times, atol=1e-12)
    diff = vertices_of(traj.scene, traj.states) - oracle_vertices(scene, times)
    error = float(np.sqrt(np.max(np.sum(diff ** 2, axis=-1))))
    assert error <= target
    assert error == pytest.approx(choice["error"], rel=1e-3, abs=1e-10)
    # the choice is the fastest centralised run that reaches the target
    reaching = [r for r in data["rows"] if r["status"] == "ok" and r["error"] <= target
                and r["kind"] != "scipy"]
    assert choice["wall"] == min(r["wall"] for r in reaching)


def test_table_errors_equal_an_independent_scipy_solve_of_paper_a2(triangles):
    """Each run's reported error (max over the run, against the package's adaptive reference)
    equals its distance from an independent tight solve of (A-2), for fixed, adaptive and
    scipy settings alike; fixed steps have the rounds per step of the registry."""
    scene = load_scene(triangles)
    result = trade(scene, 1e-6, 20.0, steps=[0.2, 0.1], tolerances=[1e-4, 1e-7])
    times = np.linspace(0.0, scene.t_end, result.samples)
    oracle = oracle_vertices(scene, times)
    assert result.samples == 21 and result.reference.floor < 1e-9
    rounds = {"lie_euler": 1, "lie_heun": 2, "rkmk4": 4, "euler_proj": 1, "rk4_proj": 4}
    for row in result.rows:
        assert row.ok, row
        s = row.setting
        if s.kind == "scipy":
            continue
        kw = {"dt": s.value} if s.kind == "fixed" else {"tolerance": s.value}
        traj = simulate(scene, s.solver, samples=times, metrics=False, **kw)
        diff = vertices_of(traj.scene, traj.states) - oracle
        want = float(np.sqrt(np.max(np.sum(diff ** 2, axis=-1))))
        assert row.error == pytest.approx(want, rel=1e-3, abs=1e-10), row
        assert row.rounds_per_step == rounds.get(s.solver), row
    scipy_rows = [r.error for r in result.rows if r.setting.kind == "scipy"]
    assert scipy_rows[1] < 0.1 * scipy_rows[0]      # it follows its tolerance


@pytest.mark.parametrize("order", [1, 2])
def test_flat_model_is_the_papers_a1_a2(order):
    """The flattened right-hand side scipy integrates is (A-2), or (A-1) with
    m W' = -gamma W + kappa/(2N) sum_k (O_k O_i^T - O_i O_k^T), written here from the paper."""
    spec = yaml.safe_load(TRIANGLES)
    spec["dimension"], spec["groups"][0]["shape"] = 3, "tetrahedron"
    if order == 2:
        spec["model"].update(order=2, mass=0.5)
        spec["groups"][0]["velocities"] = {"centroid": {"normal": 0.5},
                                           "angular": {"normal": 0.5}}
    scene = load_scene(spec)
    m, gs = scene.model, scene.initial.groups[0]
    n = m.n_agents
    flat = FlatModel(scene)
    y = flat.initial(scene)
    got = flat.unpack(flat.rhs(0.0, y))[0]
    o = rot_matrices(m.rotations, gs.rot)
    torque = np.array([sum(o[k] @ o[i].T - o[i] @ o[k].T for k in range(n))
                       for i in range(n)])
    pull = np.array([sum(gs.x[k] - gs.x[i] for k in range(n)) / n for i in range(n)])
    if order == 1:
        w = m.kappa / (2 * m.gamma * n) * torque
        assert np.allclose(got["x"], m.kappa / m.gamma * pull, atol=1e-13)
    else:
        w = skew_matrices(m.rotations, gs.w)
        assert np.allclose(got["x"], gs.v, atol=1e-13)
        assert np.allclose(got["v"], (m.kappa * pull - m.gamma * gs.v) / m.mass, atol=1e-13)
        want_w = (m.kappa / (2 * n) * torque - m.gamma * w) / m.mass
        assert np.allclose(got["w"], want_w, atol=1e-12)
    assert np.allclose(got["rot"], w @ o, atol=1e-12)


# The budget test's horizon, budget and steps: the reference fits even when the test gets a
# sixth of a core (smaller horizons and budgets were refused now and then beside busy
# processes), and the grid's finest steps, ten times finer than the default ladder's, cost each
# run ten times the default grid's dearest, so that no machine fits the grid in the budget
BUDGET_T_END = 40.0
BUDGET = 6.0   # s: far below the full grid, with room for the reference on a loaded machine
BUDGET_STEPS = [0.2, 0.1, 0.05, 0.02, 0.01, 0.005, 0.002, 0.001, 0.0005]


def test_budget_is_honoured_and_the_grid_trimmed(triangles):
    """A budget far below the full grid: the estimate is said first, the most expensive runs
    are left out or stopped, and the measurement ends within the budget (plus the last
    error's computation)."""
    spec = yaml.safe_load(TRIANGLES)
    spec["time"]["t_end"] = BUDGET_T_END
    scene = load_scene(spec)
    said = []
    start = time.perf_counter()
    result = trade(scene, 1e-6, BUDGET, steps=BUDGET_STEPS, notice=said.append)
    took = time.perf_counter() - start
    assert said and "about" in said[0]
    assert took < BUDGET + 1.5, took
    assert result.elapsed <= took
    assert any(r.status.startswith(("not run", "stopped")) for r in result.rows)
    assert result.notes and ("trimmed" in result.notes[0] or "stopped" in result.notes[0])
    assert all(r.error is not None for r in result.rows if r.ok)


def test_unreachable_target_exits_3_and_says_so(triangles_until, capsys):
    """No run reaches an error of 1e-16 (round-off alone is larger): exit 3, one line."""
    path = triangles_until(UNREACHABLE_T_END)
    code = main(["trade", path, "--target-error", "1e-16", "--budget", "2", "-q"])
    out = capsys.readouterr().out
    assert code == 3
    assert "no setting centralised reaches the target error 1e-16" in out


@pytest.mark.parametrize("argv,words", [
    (["no_such_scene.yaml"], "no such scene file"),
    (["{scene}", "--budget", "-5"], "--budget"),
    (["{scene}", "--budget", "0"], "--budget"),
    (["{scene}", "--target-error=0"], "--target-error"),
    (["{scene}", "--target-error=-1e-6"], "--target-error"),
    (["{scene}", "--budget", "1e-6"], "budget"),
    (["{scene}", "--figure", "/no/such/dir/trade.png"], "does not exist"),
])
def test_bad_input_is_one_line_and_exit_2(triangles, capsys, argv, words):
    try:
        code = main(["trade"] + [a.format(scene=triangles) for a in argv])
    except SystemExit as exc:        # argparse's own errors end the parse
        code = exc.code
    err = capsys.readouterr().err
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("polymatch: error:") and words in lines[0]
