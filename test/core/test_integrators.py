"""Integrators: Lemma 2.1 (orthogonality), observed orders, representation reductions,
stability."""

import functools
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest
from core_testlib import (
    defect,
    make_scene,
    rot_matrices,
    skew_matrices,
    state_error,
    written_out_states,
)

from polymatch_ros.core import (
    METHODS,
    PolymatchError,
    StabilityError,
    System,
    drive,
    simulate,
    with_representation,
)
from polymatch_ros.core.errors import StepLimitError
from polymatch_ros.core.metrics import ensemble_metrics
from polymatch_ros.core.model import GroupState

# ---------------------------------------------------------------------------------------------
# the registry, pinned here: name -> (order, stages, exchange rounds, model orders accepted)

METHOD_TABLE = {
    "lie_euler": (1, 1, 1, (1, 2)),
    "lie_heun": (2, 2, 2, (1, 2)),
    "rkmk4": (4, 4, 4, (1, 2)),
    "euler_proj": (1, 1, 1, (1, 2)),
    "rk4_proj": (4, 4, 4, (1, 2)),
    "etd1": (1, 1, 1, (2,)),
    "etd2": (2, 2, 2, (2,)),
    "lie_verlet": (2, 1, 1, (2,)),
}


def expected_order(method):
    return METHOD_TABLE[method][0]


def test_registry_equals_the_pinned_table_of_orders_stages_and_rounds():
    """The registry declares exactly these methods, orders, stage counts and rounds; every
    other test takes its expectations from METHOD_TABLE, never from the registry."""
    declared = {name: (m.info.order, m.info.stages, m.info.rounds, tuple(m.info.models))
                for name, m in METHODS.items()}
    assert declared == METHOD_TABLE
    assert all(m.info.name == name for name, m in METHODS.items())


# ---------------------------------------------------------------------------------------------
# Lemma 2.1: rotations stay in SO(d)

LIE_METHODS = ["lie_euler", "rkmk4", "etd2", "lie_verlet"]
LEMMA_DIMS = [(2, "matrix"), (3, "auto"), (5, "auto")]


def _lively_second_order(dim, rep, seed=1, t_end=50.0):
    """Four polytopes, weak damping: the rotations still move after 5,000 steps of dt = 0.01."""
    return make_scene(dim, 2, count=4, seed=seed, representation=rep, kappa=1.0, gamma=0.02,
                      mass=1.0, velocities={"angular": {"normal": 1.0}}, t_end=t_end,
                      samples={"every": t_end / 4})


#: Long runs for every method (each in one representation) and every representation (by at
#: least one method); every other pair for 500 steps.  The drift of Lemma 2.1 is round-off
#: of the retraction, which a representation owns, composed by the method's increments.
LONG_STEPS = {("rkmk4", 2): 2_000, ("etd2", 3): 2_000, ("lie_verlet", 5): 5_000,
              ("lie_euler", 5): 5_000}
LONG_PAIRS = set(LONG_STEPS)
SHORT_STEPS = 500

#: The defect max |O^T O - I|_F allowed per step of the run: this test's former 1e-12 after
#: 10^4 steps (long runs) and 10^3 (short).  A defect that grows linearly (a bias) is thus
#: caught as early as before, one that grows as a random walk, ~ sqrt(steps) (unbiased
#: round-off; the measured ones do, 5-D: 4e-14, 7e-14, 1.0e-13, 1.7e-13 after 250, 500, 1000,
#: 2500 steps), earlier.  Measured worst: 2-D 1.5e-14, 3-D 7.9e-15 (2,000 steps, bound 2e-13);
#: 5-D 1.7e-13 (5,000 steps, bound 5e-13: its Cayley series levels off there, up to 2.3e-13 at
#: other seeds); short runs <= 8.1e-14 (bound 5e-13).
LONG_DEFECT_PER_STEP, SHORT_DEFECT_PER_STEP = 1e-16, 1e-15


def test_long_pairs_cover_every_method_and_every_representation():
    assert {m for m, _ in LONG_PAIRS} == set(LIE_METHODS)
    assert {d for _, d in LONG_PAIRS} == {d for d, _ in LEMMA_DIMS}


@pytest.mark.slow        # the long horizon is the point
@pytest.mark.parametrize("dim,rep", LEMMA_DIMS, ids=[f"{d}d-{r}" for d, r in LEMMA_DIMS])
@pytest.mark.parametrize("method", LIE_METHODS)
def test_orthogonality_preserved_over_long_runs_lemma_2_1(method, dim, rep):
    long_run = (method, dim) in LONG_PAIRS
    steps = LONG_STEPS[method, dim] if long_run else SHORT_STEPS
    bound = steps * (LONG_DEFECT_PER_STEP if long_run else SHORT_DEFECT_PER_STEP)
    scene = _lively_second_order(dim, rep, t_end=steps * 0.01)
    # not the trivially exact angle model
    assert scene.model.rotations.name in ("matrix", "so3")
    traj = simulate(scene, method, 0.01)
    assert traj.steps == steps
    assert traj.final.t == pytest.approx(steps * 0.01)
    worst = 0.0
    for st, met in zip(traj.states, traj.metrics):
        mats = rot_matrices(scene.model.rotations, st.groups[0].rot)
        dft = defect(mats)
        worst = max(worst, dft)
        assert np.all(np.linalg.det(mats) > 0)
        assert met.groups[0].orthogonality == pytest.approx(dft, abs=1e-15)   # same to round-off
    assert worst <= bound, (worst, bound)
    # the test is not vacuous: the ensemble is still rotating at the end
    w = skew_matrices(scene.model.rotations, traj.final.groups[0].w)
    assert np.max(np.linalg.norm(w, axis=(1, 2))) > 1e-2


def test_projection_baseline_keeps_so_d_while_plain_euler_drifts_lemma_2_1():
    """euler_proj's polar projection is what keeps Lemma 2.1; without it Euler leaves SO(d).

    Each step's projection ends on SO(d) whatever came before, so the steps that test it are
    the early ones, where W is large and Euler leaves SO(d) the most: 10^3 steps sampled every
    10 (a run of 10^4 sampled at t = 0, 50, 100, after consensus, missed a single
    Newton-Schulz iteration in place of the converged polar factor: 5e-16 there, 1.7e-9 here).
    """
    scene = make_scene(3, 1, count=4, seed=2, representation="matrix",
                       t_end=10.0, samples={"every": 0.1})
    traj = simulate(scene, "euler_proj", 0.01)
    assert traj.steps == 1_000 and len(traj.states) == 101
    for st in traj.states:
        assert defect(rot_matrices(scene.model.rotations, st.groups[0].rot)) <= 1e-12
    # the same explicit Euler step O <- O + h W(O) O, transcribed here without the projection
    system = System(scene.model)
    o = np.array(scene.initial.groups[0].rot)
    for _ in range(200):
        coupling = system.couple((GroupState(None, o),))
        o = o + 0.01 * system.rotation_rate(0, o, coupling) @ o
    assert defect(o) > 1e-4


# ---------------------------------------------------------------------------------------------
# observed order of accuracy


@functools.cache            # one scene per kind, shared by its cases and its reference
def _order_scene(kind):
    vel = {"centroid": {"normal": 0.3}, "angular": {"normal": 0.5}}
    if kind == "A-2 2d":
        return make_scene(2, 1, seed=1)
    if kind == "A-2 3d":
        return make_scene(3, 1, seed=1)
    if kind == "A-1 2d":
        return make_scene(2, 2, seed=1, velocities=vel)
    if kind == "A-1 3d":
        return make_scene(3, 2, seed=1, velocities=vel)
    if kind == "A-1 3d so3-exp":
        return make_scene(3, 2, seed=1, velocities=vel, representation="so3-exp")
    if kind == "A-1 3d matrix":
        return make_scene(3, 2, seed=1, velocities=vel, representation="matrix")
    if kind == "F-1 2d":
        return make_scene(2, 2, seed=3, velocities=vel, scales={"uniform": [0.5, 2.0]})
    if kind in ("F-2 2d", "F-2 3d"):
        d = 2 if kind == "F-2 2d" else 3
        second = {"name": "g1", "shape": "square" if d == 2 else "cube", "count": 3,
                  "rotations": "uniform", "centroids": {"box": [-2.0, 2.0]}, "velocities": vel}
        return make_scene(d, 2, seed=1, velocities=vel, kappa_2=0.5, L=2.0, extra_groups=[second])
    raise KeyError(kind)


ORDER_CASES = []
for _kind in ["A-2 2d", "A-2 3d", "A-1 2d", "A-1 3d", "F-1 2d", "F-2 2d", "F-2 3d"]:
    for _name, (_order, _stages, _rounds, _models) in METHOD_TABLE.items():
        if (1 if _kind.startswith("A-2") else 2) in _models:
            ORDER_CASES.append((_kind, _name))
ORDER_CASES += [("A-1 3d so3-exp", "rkmk4"), ("A-1 3d so3-exp", "lie_heun"),
                ("A-1 3d so3-exp", "etd2"), ("A-1 3d matrix", "rkmk4"),
                ("A-1 3d matrix", "lie_verlet")]

#: the same problem (the same initial state) in another representation: one reference serves
SAME_PROBLEM_AS = {"A-1 3d so3-exp": "A-1 3d", "A-1 3d matrix": "A-1 3d"}


@functools.cache
def _reference(kind):
    """The state at t = 1: for A-1 and A-2, scipy's DOP853 of the model written out
    (``core_testlib.written_out_states``); for F-1 and F-2 (their weights and inter-group
    potential are not written out), rkmk4 at dt = 1/256 (its own error at most 8e-4 of an error
    it measures)."""
    scene = _order_scene(kind)
    if kind.startswith("F-"):
        return simulate(scene, "rkmk4", 1.0 / 256, samples=[0.0], keep_states=False,
                        metrics=False)
    return SimpleNamespace(scene=scene, final=written_out_states(scene, [1.0])[0])


@pytest.mark.parametrize("kind,method", ORDER_CASES,
                         ids=[f"{k.replace(' ', '_')}-{m}" for k, m in ORDER_CASES])
def test_observed_order_matches_declared_on_models_A_1_A_2_F_1_F_2(kind, method):
    scene = _order_scene(kind)
    ref = _reference(SAME_PROBLEM_AS.get(kind, kind))
    start = state_error(ref.scene, ref.scene.initial, scene, scene.initial)
    assert max(start.values()) == 0.0, start            # the reference solves this problem
    order = expected_order(method)
    base = 0.1 if (order < 4 or kind.startswith("F-2")) else 0.2
    errors = []
    for dt in (base, base / 2, base / 4):
        traj = simulate(scene, method, dt, samples=[0.0], keep_states=False, metrics=False)
        assert traj.final.t == pytest.approx(1.0)
        errors.append(state_error(ref.scene, ref.final, traj.scene, traj.final))
    checked = []
    for part in ("rot", "w", "x", "v"):
        e = [err[part] for err in errors]
        if e[-1] < 1e-11:          # solved exactly (decoupled centroids) or absent
            continue
        observed = np.log2(e[1] / e[2])
        assert abs(observed - order) <= 0.3, (part, e, observed)
        checked.append(part)
    assert "rot" in checked
    if kind.startswith("F-2"):
        assert "x" in checked        # F-2 centroids are integrated by the method's own stages
    else:
        # decoupled centroids use the exact flow (Prop. 2.1): no truncation error at all
        assert errors[0]["x"] < 1e-12 and errors[0]["v"] < 1e-12


# ---------------------------------------------------------------------------------------------
# representation reductions


REDUCTION_CASES = [(m, o)
                   for m in ["lie_euler", "lie_heun", "rkmk4", "rk4_proj", "etd2", "lie_verlet"]
                   for o in (1, 2) if o in METHOD_TABLE[m][3]]


@pytest.mark.parametrize("method,order", REDUCTION_CASES)
def test_so3_cayley_reduction_equals_full_matrix_model_A_1_A_2(method, order):
    scene = make_scene(3, order, count=5, seed=4, velocities={"angular": {"normal": 0.7}},
                       t_end=3.0, samples={"every": 0.5})
    assert scene.model.rotations.name == "so3" and scene.model.rotations.retraction == "cayley"
    full = with_representation(scene, "matrix")
    assert full.model.rotations.name == "matrix"
    a = simulate(scene, method, 0.05)
    b = simulate(full, method, 0.05)
    for sa, sb in zip(a.states, b.states):
        err = state_error(scene, sa, full, sb)
        assert max(err.values()) <= 1e-12, err
    np.testing.assert_allclose(a.diameters, b.diameters, rtol=0, atol=1e-12)


def _angle_vs_matrix(method, dt, order=1):
    scene = make_scene(2, order, count=5, seed=6, velocities={"angular": {"normal": 0.7}},
                       t_end=1.0)
    assert scene.model.rotations.name == "angle"
    full = with_representation(scene, "matrix")
    a = simulate(scene, method, dt, samples=[0.0], keep_states=False, metrics=False)
    b = simulate(full, method, dt, samples=[0.0], keep_states=False, metrics=False)
    return max(state_error(scene, a.final, full, b.final).values())


@pytest.mark.parametrize("method,order", [("lie_euler", 1), ("rkmk4", 1), ("rkmk4", 2),
                                          ("etd2", 2), ("lie_verlet", 2)])
def test_angle_reduction_same_trajectory_as_matrix_model_A_1_A_2(method, order):
    """Model only what the scene requires: 2-D angles are the full 2x2 model, to round-off."""
    assert _angle_vs_matrix(method, 0.05, order) <= 1e-12


# ---------------------------------------------------------------------------------------------
# adaptive DOP853-Lie


@pytest.mark.parametrize("order", [1, 2])
def test_adaptive_dop853_lie_accuracy_and_orthogonality_lemma_2_1(order):
    velocities = {"angular": {"normal": 0.5}, "centroid": {"normal": 0.3}}
    scene = make_scene(3, order, count=5, seed=5, velocities=velocities, t_end=5.0)
    ada = simulate(scene, "adaptive", tolerance=1e-10, samples=[0.0, 2.5, 5.0])
    assert ada.final.t == pytest.approx(5.0)
    assert ada.steps > 3 and ada.rhs_evals > ada.steps
    ref = simulate(scene, "rkmk4", 0.01, samples=[0.0], keep_states=False, metrics=False)
    err = state_error(scene, ada.final, scene, ref.final)
    assert max(err.values()) <= 1e-8, err
    for st in ada.states:
        assert defect(rot_matrices(scene.model.rotations, st.groups[0].rot)) <= 1e-14
    # and it is much cheaper than the fixed-step reference
    assert ada.rhs_evals < 4 * 500 / 2


def test_adaptive_max_steps_bounds_accepted_and_rejected_steps():
    scene = make_scene(2, 1, count=4, seed=5, t_end=5.0)
    scene = replace(scene, integrator=replace(scene.integrator, max_steps=5))
    with pytest.raises(StepLimitError) as exc:
        simulate(scene, "adaptive", tolerance=1e-8, keep_states=False, metrics=False)
    msg = str(exc.value)
    assert "\n" not in msg and "max_steps = 5" in msg and exc.value.exit_code == 1


@pytest.mark.parametrize("tolerance", [1e-30, 1e-200])
def test_adaptive_tolerance_beyond_double_precision_refused_in_one_line(tolerance):
    scene = make_scene(2, 1, count=4, seed=5, t_end=5.0)
    with pytest.raises(PolymatchError) as exc:
        simulate(scene, "adaptive", tolerance=tolerance, keep_states=False, metrics=False)
    msg = str(exc.value)
    assert "\n" not in msg and "beyond double precision" in msg


def test_stability_error_fields_match_its_message():
    second, _ = _stiff_pair()
    with pytest.raises(StabilityError) as exc:
        simulate(second, "rkmk4", 0.01, keep_states=False, metrics=False)
    err = exc.value
    assert err.method == "rkmk4" and err.dt == 0.01 and 0 < err.limit < 0.01
    assert f"dt < {err.limit:.3g} ({err.cause}" in str(err)
    # the damping mode -gamma/m is the fastest: RK4's real boundary (2.785) times m/gamma
    rk4 = _rk_real_stability_boundary([1.0, 1.0, 1 / 2, 1 / 6, 1 / 24])
    assert rk4 == pytest.approx(2.785293563, rel=1e-8)
    assert err.limit == pytest.approx(rk4 * 1e-8 / 2.0, rel=1e-3)


def test_adaptive_final_state_at_t_end_like_fixed_step_theorem_4_2():
    """Both runs end at t_end and in the same state: rotations within rkmk4's O(dt^4)
    truncation error at dt = 0.05 (~1e-8, bound 1e-7), centroids (the exact flow of
    Prop. 2.1 in both) to round-off."""
    scene = make_scene(2, 1, count=4, seed=5, t_end=5.0)
    fixed = simulate(scene, "rkmk4", 0.05, samples=[0.0, 1.0], keep_states=False, metrics=False)
    assert fixed.final.t == pytest.approx(5.0)
    ada = simulate(scene, "adaptive", tolerance=1e-10,
                   samples=[0.0, 1.0], keep_states=False, metrics=False)
    assert ada.final.t == pytest.approx(5.0)
    err = state_error(scene, fixed.final, scene, ada.final)
    assert err["rot"] <= 1e-7 and err["x"] <= 1e-12, err
    # not vacuous: both runs moved far from the initial state
    moved = state_error(scene, scene.initial, scene, ada.final)
    assert moved["rot"] > 0.1 and moved["x"] > 0.1, moved


@pytest.mark.parametrize("method", sorted(METHOD_TABLE))
def test_exchange_rounds_per_step_equal_the_pinned_table(method):
    """Each step asks the ensemble for its arrays once per exchange round (what a lockstep
    agent publishes), counted through the driver's answer hook over three steps; a method
    that reuses its last evaluation (FSAL) pays one extra round on the first step only."""
    order = METHOD_TABLE[method][3][-1]
    scene = make_scene(3, order, count=4, seed=2, velocities={"angular": {"normal": 0.5}}
                       if order == 2 else None)
    system, state, asked = System(scene.model), scene.initial, []
    for _ in range(3):
        calls = []

        def answer(request, stage, calls=calls):
            calls.append(stage)
            return request.stage.groups

        state = drive(METHODS[method], system, state, 0.01, answer)
        asked.append(len(calls))
    rounds = METHOD_TABLE[method][2]
    assert asked[1:] == [rounds, rounds], asked
    assert asked[0] in (rounds, rounds + 1), asked


# ---------------------------------------------------------------------------------------------
# stiff damping: m -> 0 (first-order limit of Section 4.1.4)


def _stiff_pair(dt=0.01):
    kw = dict(count=5, seed=7, kappa=1.5, gamma=2.0, t_end=2.0, samples={"every": 0.1}, dt=dt)
    return make_scene(3, 2, mass=1e-8, **kw), make_scene(3, 1, **kw)


def _rk_real_stability_boundary(coefs):
    """Largest x with |R(-x)| <= 1 on the negative real axis, R(z) = sum coefs[k] z^k
    (bisection)."""
    def ok(x):
        return abs(sum(c * (-x) ** k for k, c in enumerate(coefs))) <= 1.0
    lo, hi = 1e-6, 10.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if ok(mid) else (lo, mid)
    return lo


@pytest.mark.parametrize("method", ["lie_euler", "lie_heun", "rkmk4", "euler_proj", "rk4_proj",
                                    "lie_verlet"])
def test_explicit_methods_refuse_stiff_mass_A_1(method):
    second, _ = _stiff_pair()
    with pytest.raises(StabilityError) as exc:
        simulate(second, method, 0.01, keep_states=False, metrics=False)
    msg = str(exc.value)
    assert "\n" not in msg
    assert "dt <" in msg and method in msg
    limit = exc.value.limit
    # independent limit: the fastest eigenvalue of m xi'' = -gamma xi' - kappa xi
    lam = np.linalg.eigvals(np.array([[0.0, 1.0], [-1.5 / 1e-8, -2.0 / 1e-8]]))
    fast = float(np.max(np.abs(lam)))
    if method == "lie_verlet":
        # damping is exact; the kick-drift-kick is stable for h < 2 / sqrt(kappa / m)
        expected = 2.0 / np.sqrt(1.5 / 1e-8)
    else:
        taylor = {1: [1, 1], 2: [1, 1, 1 / 2], 4: [1, 1, 1 / 2, 1 / 6, 1 / 24]}
        coefs = taylor[expected_order(method)]
        expected = _rk_real_stability_boundary(coefs) / fast
    assert limit == pytest.approx(expected, rel=5e-3)


def test_etd2_stiff_mass_tends_to_first_order_model_A_2():
    second, first = _stiff_pair()
    # the first-order model once, at the finer dt: rkmk4's O(dt^4) error there (its run at
    # dt = 0.01 is 3e-12 away) is far below etd2's O(dt^2) one (1e-6 and 4e-6)
    b = simulate(first, "rkmk4", 0.005)
    results = []
    for dt in (0.01, 0.005):
        a = simulate(second, "etd2", dt)
        assert len(a.diameters) == len(b.diameters) == 21
        assert a.diameters[-1] < 0.6 * a.diameters[0]           # something happened
        diam = float(np.max(np.abs(a.diameters - b.diameters)))
        err = state_error(second, a.final, first, b.final)
        assert diam < 1e-3 and err["rot"] < 1e-3
        # O(m/gamma) for the exact centroid flow
        assert err["x"] < 1e-7
        results.append(err["rot"])
        for st in a.states:
            m = ensemble_metrics(second.model, st)
            assert np.isfinite(m.diameter)
    # the remaining difference is etd2's O(dt^2) truncation error, not an O(1) model mismatch
    assert np.log2(results[0] / results[1]) == pytest.approx(2.0, abs=0.3)
