"""Sweeps (core.batch, core.sweep): a batch equals separate simulate runs; Theorem 4.2; CLI."""

from types import SimpleNamespace

import numpy as np
import pytest
from input_fuzz import run_main
from scipy.integrate._ivp import dop853_coefficients

from polymatch_ros.core import METHODS, simulate
from polymatch_ros.core.stepping.rk import RKMK
from polymatch_ros.core.sweep.batch import HalfAngles, pair_diameters
from polymatch_ros.core.sweep.run import batch_plan, classify, run_batch
from polymatch_ros.core.sweep.scenes import Cell, cell_scenes, rotations_at_diameter, template

CASES = [  # (template, cell): angles, SO(3) SoA, SO(4) matrices; both model orders
    ("congruent_triangles", Cell(agents=5)),
    ("congruent_triangles_second_order", Cell(agents=4)),
    ("congruent_triangles", Cell(dim=3, agents=4, order=2, mass=0.5)),
    ("congruent_triangles", Cell(dim=4, agents=3, kappa=2.0)),
]


@pytest.mark.parametrize("name,cell", CASES)
def test_batch_equals_separate_simulate_runs(name, cell):
    """The key claim: B ensembles in one batch = B `simulate` runs, to round-off."""
    scenes = _short_scenes(name, cell)
    _assert_equals_simulate_runs(scenes, run_batch(scenes))


def _short_scenes(name, cell, ensembles=5):
    """``ensembles`` of the cell to t = 8, at dt = 0.25 (the templates' 0.05; samples every 2
    steps): both sides of the comparison step alike, and the same ensembles match, at the same
    samples, as at dt = 0.05."""
    data = template(name)
    data["time"] = dict(data["time"], t_end=8.0)
    data["integrator"] = dict(data["integrator"], dt=0.25)
    data["convergence"] = {"tolerance": 1e-2}      # some ensembles leave the batch early
    return cell_scenes(data, cell, ensembles, seed=3)


def _assert_equals_simulate_runs(scenes, result, method=None, dt=None):
    for b, scene in enumerate(scenes):
        traj = simulate(scene, method, dt, stop_when_converged=True)
        grp = traj.scene.model.rotations
        final = traj.final.groups[0]
        assert result.final_t[b] == traj.times[-1]
        assert (np.isnan(result.converged_at[b]) and traj.converged_at is None) or \
            result.converged_at[b] == traj.converged_at
        np.testing.assert_allclose(result.final_x[b], final.x, rtol=0, atol=1e-12)
        np.testing.assert_allclose(result.final_rot[b], grp.to_matrices(final.rot),
                                   rtol=0, atol=1e-12)
        t = len(traj.times)
        np.testing.assert_allclose(result.diameters[:t, b], traj.diameters, rtol=1e-10,
                                   atol=1e-12)
        assert np.all(np.isnan(result.diameters[t:, b]))
    assert np.any(~np.isnan(result.converged_at))


@pytest.mark.parametrize("name,cell", CASES)
def test_rkmk8_batch_equals_separate_runs_of_its_tableau(name, cell, monkeypatch):
    """rkmk8 over a batch (stage sums as matrix products, ``ChartRK``) = B `simulate` runs
    of the plain RKMK of DOP853's tableau as scipy ships it (``dop853_coefficients``: one array
    update per stage term), to round-off.
    Three ensembles (the 12-stage separate runs are the cost): in every cell some leave the
    batch while others go on (leaving at t = 7.5, 8, never; 7.5, 7, 8; 7.5, never, never;
    4.5, 4.5, 4)."""
    stages = dop853_coefficients.N_STAGES
    a = [list(row) for row in dop853_coefficients.A[:stages, :stages]]
    b = list(dop853_coefficients.B)
    monkeypatch.setitem(METHODS, "dop853_tableau", RKMK("dop853_tableau", a, b, 8,
                                                        "the plain RKMK of scipy's DOP853"))
    scenes = _short_scenes(name, cell, ensembles=3)
    result = run_batch(scenes, "rkmk8", 0.25)
    assert (result.method, result.dt, result.rhs_evals) == ("rkmk8", 0.25, 12 * result.steps)
    _assert_equals_simulate_runs(scenes, result, "dop853_tableau", 0.25)


def test_rkmk8_is_eighth_order_and_defaults_to_the_sample_interval():
    """Halving the step divides rkmk8's error by 2^7 or more (DOP853's order 8; at these
    steps the run is not yet asymptotic: 2^10 here), as no 4th-6th order method would."""
    data = template("congruent_triangles")
    data["time"] = {"t_end": 4.0, "samples": {"every": 1.0}}
    data["convergence"] = {"tolerance": 1e-14}         # none matches by t = 4
    scenes = cell_scenes(data, Cell(agents=5), 3, seed=1)
    assert batch_plan(scenes[0], "rkmk8").dt == 1.0
    exact = run_batch(scenes, "rkmk8", 1 / 16).final_rot     # 6e-16 from h = 1/64's: round-off
    errors = [np.abs(run_batch(scenes, "rkmk8", h).final_rot - exact).max() for h in (1.0, 0.5)]
    assert errors[0] < 1e-4 and 7.0 < np.log2(errors[0] / errors[1]) < 11.0, errors


def test_half_angle_cos_sin_are_np_cos_sin_to_one_ulp():
    angles = np.concatenate([np.random.default_rng(0).uniform(-60, 60, 100_000),
                             np.pi / 2 * np.arange(-40, 41), [1e-300, -5e-9]])
    c, s = HalfAngles()._cos_sin(angles)
    assert np.abs(c - np.cos(angles)).max() <= 2.3e-16
    assert np.abs(s - np.sin(angles)).max() <= 2.3e-16


def test_pair_diameters_are_the_largest_pair_distance():
    points = np.random.default_rng(2).standard_normal((7, 5, 3, 4))    # (B, N, vertices, k)
    laid_out = np.ascontiguousarray(points.transpose(2, 3, 1, 0))      # (vertices, k, N, B)
    diff = points[:, :, None] - points[:, None]
    brute = np.sqrt((diff ** 2).sum(-1)).max(axis=(1, 2, 3))
    np.testing.assert_allclose(pair_diameters(laid_out), brute, rtol=1e-14, atol=0)


def test_d0_below_one_all_match_first_order():
    """Theorem 4.2: first order, D0 < 1: every ensemble matches (d = 2 and 3).  At dt = 0.25 (the
    template's 0.05) every ensemble matches at the same sample, its diameter there (0.963 and
    0.990 of the tolerance at most) within 6e-5 (relative) of the dt = 0.05 run's."""
    data = template("congruent_triangles")
    data["integrator"] = dict(data["integrator"], dt=0.25)
    for cell in (Cell(dim=2, agents=6), Cell(dim=3, agents=4)):
        scenes = cell_scenes(data, cell, 40, seed=11, d0=(0.0, 0.99))
        result = run_batch(scenes)
        assert result.initial_rotation.max() < 1.0
        assert result.initial_rotation.max() > 0.9
        assert np.all(result.outcome == "matched"), result.outcome
        assert np.all(result.final_matching < scenes[0].tolerance)
        # the verdict against the vertices themselves, x^i_a = xbar_i + O_i r_a
        brute = brute_matching_diameters(scenes, result)
        np.testing.assert_allclose(result.final_matching, brute, rtol=1e-9, atol=1e-15)
        assert np.all(brute < scenes[0].tolerance), brute
        initial = [_vertex_diameter(sc.initial.groups[0].x, sc.model.rotations.to_matrices(
            sc.initial.groups[0].rot), sc.model.groups[0].reference) for sc in scenes]
        assert min(initial) > 100 * scenes[0].tolerance      # something had to happen


def _vertex_diameter(x, mats, reference):
    """max_{i,j,a} |x^i_a - x^j_a| with x^i_a = xbar_i + O_i r_a (congruent: s_i = 1), by brute
    force over every pair of polytopes and every vertex."""
    verts = x[:, None, :] + np.einsum("nij,aj->nai", mats, reference)     # (N, n, d)
    diff = verts[:, None] - verts[None, :]                                  # (N, N, n, d)
    return float(np.sqrt((diff ** 2).sum(axis=-1)).max())


def brute_matching_diameters(scenes, result):
    """The matching diameter of every ensemble's final state, from its vertices."""
    return np.array([_vertex_diameter(result.final_x[b], result.final_rot[b],
                                      sc.model.groups[0].reference)
                     for b, sc in enumerate(scenes)])


def test_rotations_at_diameter_hit_the_target():
    targets = np.array([0.0, 0.5, 1.0, 1.7, 2.5])
    for d in (2, 3, 4):
        mats = rotations_at_diameter(d, 6, targets, range(5))
        flat = mats.reshape(5, 6, -1)
        diam = np.linalg.norm(flat[:, :, None] - flat[:, None], axis=-1).max(axis=(1, 2))
        np.testing.assert_allclose(diam, targets, atol=1e-9)
        np.testing.assert_allclose(np.swapaxes(mats, -1, -2) @ mats, np.broadcast_to(
            np.eye(d), mats.shape), atol=1e-12)
        np.testing.assert_allclose(np.linalg.det(mats), 1.0, atol=1e-12)


def test_antipodal_and_twisted_end_states_are_classified():
    """Equilibria that are not consensus: a half-turn split and a splay state (S = 0)."""
    data = template("congruent_triangles")
    data["time"] = dict(data["time"], t_end=2.0)
    scenes = cell_scenes(data, Cell(agents=4), 2, seed=0)
    from polymatch_ros.core.sweep.scenes import with_rotations

    def rot(a):
        return np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    scenes[0] = with_rotations(scenes[0], np.array([rot(a) for a in (0.3, 0.3, 0.3 + np.pi,
                                                                      0.3)]))
    scenes[1] = with_rotations(scenes[1], np.array([rot(np.pi * k / 2) for k in range(4)]))
    result = run_batch(scenes)
    assert list(result.outcome) == ["antipodal", "twisted"]
    assert classify(np.array([np.nan]), np.array([1.0]), np.array([1.0]),
                    np.array([1.0]))[0] == "too slow"
    # not matched: the vertices stay apart, computed here from the final poses
    brute = brute_matching_diameters(scenes, result)
    assert np.all(brute > 1.0) and np.all(np.isnan(result.converged_at)), brute
    # the end-state measures against their definitions: |mean_i O_i|_F / sqrt(d) (1/2 for
    # three against one at a half-turn, 0 for the splay state) and
    # max_{k,l} |O_k^T O_l - O_l^T O_k|_F (0 when every relative rotation is +-I)
    mats = result.final_rot
    order = np.linalg.norm(mats.mean(axis=1), axis=(1, 2)) / np.sqrt(2)
    np.testing.assert_allclose(result.order_parameter, order, atol=1e-12)
    np.testing.assert_allclose(order, [0.5, 0.0], atol=1e-9)
    rel = np.einsum("bkji,bljm->bklim", mats, mats)
    asym = np.linalg.norm(rel - np.swapaxes(rel, -1, -2), axis=(-2, -1)).max(axis=(1, 2))
    np.testing.assert_allclose(result.asymmetry, asym, atol=1e-12)
    assert asym[0] < 1e-9 and asym[1] == pytest.approx(2 * np.sqrt(2), abs=1e-9)
    assert np.all(result.stationarity < 1e-9), result.stationarity


def _cli(*args):
    """`polymatch sweep ARGS` in this process (the console script's own path is tested in
    test_extremes and test_input_contract): its exit code, stdout and stderr."""
    code, out, err = run_main(["sweep", *map(str, args)], seconds=60)
    return SimpleNamespace(returncode=code, stdout=out, stderr=err)


BAD_ARGUMENTS = [  # (arguments, the words of the one error line)
    (["--ensembles", "0"], "argument --ensembles/-B: must be in 1..100000, got 0"),
    (["--d0", "2,1"], "--d0: expected LO,HI with LO <= HI, got 2,1"),
    (["--d0", "a,1"], "argument --d0: expected a rotation diameter, got 'a'"),
    (["--agents", "1"], "argument --agents: an agent count must be >= 2, got 1"),
    (["--dimension", "2,x"], "argument --dimension: expected a dimension, got 'x'"),
    (["--kappa", "-1"], "argument --kappa: kappa must be >= 0.0, got -1"),
    (["--integrator", "adaptive"], "a sweep takes fixed-step integrators"),
    (["--integrator", "nope"], "unknown integrator 'nope'; known: "),
    (["no_such_scene"], "no_such_scene: no such scene file"),
    (["mixed_triangles_tetrahedra"], "a sweep takes a scene with exactly one group"),
    (["radio_connected"], "a sweep takes fixed graphs (complete, ring, k_nearest, random, edges), "
                          "not a proximity graph"),
    (["--order", "3"], "model.order: must be 1 (A-2) or 2 (A-1), got 3"),
    (["--order", "2", "--mass", "0"], "model.mass: the second-order model needs m > 0, got 0.0"),
    (["-B", "100000", "--agents", "5000"],
     "100000 ensembles of 5000 agents in d = 2 need about"),
    (["--save", "/no/such/dir/out.npz"],
     "/no/such/dir/out.npz: the directory /no/such/dir does not exist"),
    (["--figure", "/no/such/dir/f.png"],
     "/no/such/dir/f.png: the directory /no/such/dir does not exist"),
    (["--dt", "0"], "argument --dt: must be a positive finite number, got 0"),
    (["--graph", "ring:x"], "argument --graph: ring takes an integer, got 'x'"),
]


@pytest.mark.parametrize("args,words", BAD_ARGUMENTS, ids=[" ".join(a) for a, _ in BAD_ARGUMENTS])
def test_bad_arguments_exit_2_with_one_line(args, words):
    proc = _cli("-B", "2", "--t-end", "1", "-q", *args)
    assert proc.returncode == 2, (args, proc.stderr)
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("polymatch: error: " + words), proc.stderr


def test_cli_sweep_saves_outcomes(tmp_path):
    """--dt 0.25 (the scene's 0.05): the same outcomes, sample times and loop measures, saved."""
    out = tmp_path / "sweep.npz"
    proc = _cli("-B", "3", "--agents", "3,4", "--graph", "complete,ring:1", "--normalise",
                "degree", "--t-end", "20", "--dt", "0.25", "-q", "--save", str(out))
    assert proc.returncode == 0, proc.stderr
    assert "matched" in proc.stdout and "ring:1" in proc.stdout
    data = np.load(out, allow_pickle=False)
    assert list(data["N"]) == [3] * 6 + [4] * 6
    assert list(data["graph"]) == (["complete"] * 3 + ["ring:1"] * 3) * 2
    assert data["outcome"].shape == (12,)
    assert np.all(data["outcome"] == "matched"), data["outcome"]    # as at the scene's dt
    ring = data["graph"] == "ring:1"
    assert np.all(np.isnan(data["winding"][~ring])) and np.all(data["winding"][ring] % 1 == 0)
    assert np.all(np.abs(data["loop_class"][ring]) == 1)


def test_cli_sweep_with_rkmk8_steps_by_the_sample_interval():
    proc = _cli("-B", "3", "--integrator", "rkmk8", "--t-end", "20", "-q")
    assert proc.returncode == 0, proc.stderr
    assert "integrator rkmk8 dt = 0.5" in proc.stdout
    unstable = _cli("-B", "2", "--integrator", "rkmk8", "--dt", "8", "--t-end", "20", "-q")
    assert unstable.returncode == 2 and "rkmk8 is unstable at dt = 8" in unstable.stderr
