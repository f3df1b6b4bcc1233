"""Adaptive Lie DOP853 against scipy's DOP853 on the flattened system, at a target error.

Scene: ``congruent_triangles`` (Fig. 1; 2-D, first-order model (A-2), N = 8).
Solvers, each at rtol = atol = tol for tol in 1e-3 ... 1e-12:

  ours (angle)      ``simulate(scene, "adaptive", tolerance=tol)``: scipy's DOP853 tableau and
                    step control as a Munthe-Kaas method; in 2-D the rotations are angles (SO(2)
                    is abelian, so (A-2)_2 is Kuramoto) and centroids follow the exact flow of
                    Proposition 2.1 (no evaluations, no step-size limit).
  ours (matrix)     the same in the general 2x2 matrix representation with the Cayley map.
  scipy DOP853      ``solve_ivp(method="DOP853")`` on y = (centroids (N, 2), O (N, 2, 2)) flattened
                    (``benchmarks/core_families/paper_rhs.py``), right-hand side (A-2) written
                    directly with numpy:
                        xbar_i' = kappa/N sum_k (xbar_k - xbar_i),
                        O_i'    = kappa/(2N) sum_k (O_k O_i^T - O_i O_k^T) O_i
                    (the sum taken through S = sum_k O_k); centroids are integrated too, and
                    nothing keeps O_i in SO(2) (Lemma 2.1 holds for the ODE, not for the method).

Error = max over time and over all vertices of |x^i_a - x^i_a(ref)|, with
x^i_a = xbar_i + O_i r_a, measured two ways:

  A  "301 outputs": at 301 sample times on [0, t_end], both from their dense output
     (DOP853's continuous extension; ours evaluates it in the Cayley/angle chart).
  B  "own steps": the run asks for the final state only and the error is taken at
     every step the solver accepted (ours: ``on_step``; scipy: ``t_eval=None``).
     This is the integrator's own accuracy for its cost.

References: rkmk4 at dt = 1e-3 on the 301 sample times; ours at tol = 1e-13 at
arbitrary times (B); the two are compared on the sample times.  A repeat is one sweep of every
tolerance, solvers interleaved; ours/scipy at each target 1e-4 ... 1e-10 is given of the best
walls and as the median of the sweeps' own ratios.
"""

import math
from dataclasses import dataclass

import numpy as np

from ..timing import fmt_ms

NAME = "dop853"
HELP = "adaptive Lie DOP853 vs scipy solve_ivp DOP853 on congruent_triangles, cost per max error"

TARGET_ERROR = 1e-8
#: error targets of the ratio table (max error over time, ours against scipy's)
RATIO_TARGETS = tuple(10.0 ** -k for k in range(4, 11))


def add_arguments(p):
    from ..options import at_least, float_list

    small = at_least(1e-300, float)
    p.add_argument("--scene", default="congruent_triangles",
                   help="first-order, single-group congruent scene (default congruent_triangles)")
    p.add_argument("--tolerances", type=float_list(1e-300),
                   default=[10.0**-k for k in range(3, 13)],
                   help="rtol = atol values (default 1e-3,1e-4,...,1e-12)")
    p.add_argument("--samples", type=at_least(2), default=301,
                   help="sample times on [0, t_end] (default 301)")
    p.add_argument("--target", type=small, default=TARGET_ERROR,
                   help="target max error (default 1e-8)")
    p.add_argument("--ref-dt", type=small, default=1e-3,
                   help="rkmk4 reference step (default 1e-3)")
    p.add_argument("--ref-tol", type=small, default=1e-13,
                   help="tolerance of the adaptive reference (default 1e-13)")
    p.add_argument("--t-end", type=at_least(1e-300, float), help="override time.t_end")


# -- runs -------------------------------------------------------------------------------------


def _verts(scene, out):
    from polymatch_ros.core.metrics import vertices

    return vertices(out.centroids, out.mats, scene.model.groups[0].reference)


def _core_own_steps(scene, tol):
    """(times, vertices, rotations) at every step ours accepts when asked for t_end only."""
    from polymatch_ros.core import AdaptiveLie, State, System
    from polymatch_ros.core.metrics import vertices

    from .solve import state_arrays

    m = scene.model
    accepted = [scene.initial]
    run = AdaptiveLie(tol, max_steps=scene.integrator.max_steps).solver(
        System(m), State(0.0, scene.initial.groups), scene.t_end
    )
    while run.status == "running":
        run.step()
        accepted.append(run.state)
    times = np.array([0.0] + [st.t for st in accepted[1:]])
    cents, mats, _w = state_arrays(scene, accepted)
    return times, vertices(cents, mats, m.groups[0].reference), mats


def _check_scene(scene):
    from polymatch_ros.core import SceneError

    m = scene.model
    if m.order != 1 or len(m.groups) != 1 or m.groups[0].scales is not None or m.inter_group:
        raise SceneError(
            f"{scene.name}: `python -m benchmarks dop853` needs a first-order (A-2), "
            f"single-group, congruent scene (the scipy right-hand side is written for that case)"
        )


class _Reference:
    """Vertex positions of the tight adaptive reference (ours at ref_tol) at any times."""

    def __init__(self, scene, tol):
        self.scene, self.tol = scene, tol

    def at(self, times):
        from .solve import Solver, solve

        ts = np.asarray(times, dtype=float)
        out = solve(
            self.scene,
            Solver("adaptive", "adaptive", self.tol),
            np.concatenate([[0.0], ts[ts > 0]]),
        )
        v = _verts(self.scene, out)
        return v if ts[0] == 0 else v[1:]


# -- the benchmark ----------------------------------------------------------------------------


def _runs(sc, scene, tol, times):
    """One timed run A (outputs at ``times``) and one timed run B (final state only)."""
    from .solve import Solver, solve

    if sc is None:
        scipy = Solver("DOP853", "scipy", tol)
        return solve(scene, scipy, times), solve(scene, scipy, None)
    ours = Solver("adaptive", "adaptive", tol)
    return solve(sc, ours, times), solve(sc, ours, np.array([0.0, scene.t_end]))


def _row(label, sc, scene, tol, runs, ref_dense, ref):
    """Wall/evals/error on the sample times (A) and on the solver's own steps (B), timed."""
    from polymatch_ros.core.metrics import orthogonality

    from ..timing import Timing

    dense_w = [a.wall for a, _ in runs]
    end_w = [b.wall for _, b in runs]
    dense_t, end_t = Timing(tuple(dense_w)), Timing(tuple(end_w))
    out, out_end = runs[-1]
    if sc is None:  # t_eval does not change scipy's steps
        own_t, own_v, own_m = out_end.times, _verts(scene, out_end), out_end.mats
        steps = out_end.steps
    else:
        own_t, own_v, own_m = _core_own_steps(sc, tol)
        steps = out.steps
    err = float(np.abs(_verts(scene, out) - ref_dense).max())
    err_own = float(np.abs(own_v - ref.at(own_t)).max())
    return {
        "solver": label,
        "tol": tol,
        "wall": dense_t.best,
        "wall_med": dense_t.median,
        "walls": dense_w,
        "walls_end": end_w,
        "evals": out.evals,
        "steps": steps,
        "err": err,
        "wall_end": end_t.best,
        "wall_end_med": end_t.median,
        "evals_end": out_end.evals,
        "steps_end": out_end.steps,
        "err_own": err_own,
        "orth": orthogonality(own_m[-1]),
    }


@dataclass(frozen=True)
class _Settings:
    """The run's scene, tolerances, sample count, references and repeats (--quick: tiny)."""

    scene: object
    tols: list
    n_samples: int
    ref_dt: float
    ref_tol: float
    repeats: int
    target: float


def _settings(args):
    """Settings from the options; a scene the scipy right-hand side cannot model is refused."""
    from polymatch_ros.core import load_scene
    from polymatch_ros.core.scenes.scene import resolve_scene_path

    t_end = args.t_end if args.t_end is not None else (5.0 if args.quick else None)
    scene = load_scene(resolve_scene_path(args.scene), {"time.t_end": t_end})
    _check_scene(scene)
    if args.quick:
        tols, n_samples, ref_dt, ref_tol = [1e-6, 1e-8], 11, 1e-2, 1e-11
    else:
        tols = list(args.tolerances)
        n_samples, ref_dt, ref_tol = args.samples, args.ref_dt, args.ref_tol
    return _Settings(scene, tols, n_samples, ref_dt, ref_tol,
                     args.repeats or (1 if args.quick else 9), args.target)


def _intro(report, s, wall_ref, ref_gap, shift):
    """The scene, the two error measures and how far the two references agree."""
    from ..timing import fmt_ms

    scene = s.scene
    report.text(
        f"Scene `{scene.name}`: d = {scene.dim}, N = {scene.model.n_agents}, first-order model "
        f"(A-2), t_end = {scene.t_end:g}.  Error = max over time and all vertices of "
        f"|x^i_a - x^i_a(ref)|: (A) on {s.n_samples} sample times, (B) on the solver's own "
        "accepted steps.",
        "",
        f"References: rkmk4 at dt = {s.ref_dt:g} ({fmt_ms(wall_ref)} ms) on the sample times; "
        f"ours at tol = {s.ref_tol:g} at any time.  They differ by at most {ref_gap:.1e} on the "
        "sample times, so errors well above that are resolved."
        + (f"  WARNING: the rkmk4 sample times are rounded to its steps (shift {shift:.1e})."
           if shift > 1e-12 else ""),
    )


def _sweeps(s, solvers, times, log):
    """``s.repeats`` sweeps of every tolerance, solvers round-robin (a burst of machine load
    hits every solver alike); (label, tol) -> that solver's (A, B) runs."""
    runs = {(label, tol): [] for label in solvers for tol in s.tols}
    for k in range(s.repeats):
        log(f"dop853: sweep {k + 1} of {s.repeats}: every tolerance, solvers interleaved")
        for tol in s.tols:
            for label, sc in solvers.items():
                runs[label, tol].append(_runs(sc, s.scene, tol, times))
    return runs


def run(args, log):
    from functools import partial

    from polymatch_ros.core import with_representation

    from ..report import Report
    from .solve import Solver, solve

    report = Report(NAME, "Adaptive Lie DOP853 vs scipy DOP853 (`python -m benchmarks dop853`)")
    s = _settings(args)
    scene = s.scene
    times = np.linspace(0.0, scene.t_end, s.n_samples)
    log(f"dop853: reference rkmk4 dt = {s.ref_dt:g} on {scene.name}")
    ref1 = solve(scene, Solver("rkmk4", "fixed", s.ref_dt), times)
    ref_dense, ref = _verts(scene, ref1), _Reference(scene, s.ref_tol)
    ref_gap = float(np.abs(ref.at(times) - ref_dense).max())
    shift = float(np.abs(ref1.times - times).max())
    solvers = {OURS: scene, "ours (matrix, Cayley)": with_representation(scene, "matrix"),
               THEIRS: None}
    runs = _sweeps(s, solvers, times, log)
    results = [_row(label, sc, scene, tol, runs[label, tol], ref_dense, ref)
               for label, sc in solvers.items() for tol in s.tols]
    _intro(report, s, ref1.wall, ref_gap, shift)
    sweep_table(report, results, s.repeats, s.n_samples)
    target_tables(report, results, solvers, s.target, s.n_samples)
    ratio_tables(report, results, s.tols, RATIO_TARGETS, s.repeats)
    notes(report, s.target)
    report.figure("work_precision",
                  partial(draw_work_precision, results, solvers, s.target, s.repeats,
                          scene.name, s.n_samples),
                  "wall time against max error, and orthogonality defect")
    return report


# -- tables, notes and figure from the per-run results --------------------------------------

OURS, THEIRS = "ours (angle)", "scipy DOP853"
TARGET_HEADER = ["solver", "loosest tol", "its max error", "wall ms (best)", "rhs evals",
                 "µs/eval", "wall ms interpolated"]


def interpolate(points, target):
    """log-log interpolation of wall time at error = target from (error, wall) points, or None."""
    pts = sorted(p for p in points if p[0] > 0)
    for (e1, w1), (e2, w2) in zip(pts, pts[1:]):
        if e1 <= target <= e2 and e1 < e2:
            f = (math.log(target) - math.log(e1)) / (math.log(e2) - math.log(e1))
            return math.exp(math.log(w1) + f * (math.log(w2) - math.log(w1)))
    return None


def _of(results, label):
    return [r for r in results if r["solver"] == label]


def sweep_table(report, results, repeats, n_samples):
    """Every solver at every tolerance: A (sample times) and B (own steps) side by side."""
    rows = [[r["solver"], f"{r['tol']:.0e}", fmt_ms(r["wall"]), r["evals"], r["steps"],
             f"{r['err']:.2e}", fmt_ms(r["wall_end"]), fmt_ms(r["wall_end_med"]), r["evals_end"],
             r["steps_end"], f"{r['err_own']:.2e}", f"{r['orth']:.1e}"] for r in results]
    report.table(
        ["solver", "rtol=atol", f"A: wall ms, best of {repeats}", "A: evals", "A: steps",
         f"A: max err ({n_samples} times)", f"B: wall ms, best of {repeats}", "B: median ms",
         "B: evals", "B: steps", "B: max err (own steps)", "orth. defect"],
        rows,
        caption=f"Tolerance sweep. A: outputs at {n_samples} sample times; B: final state only "
        "(error on its own steps); repeats interleaved across solvers. "
        "orth. defect: max_i |O_i^T O_i - I|_F at t_end",
    )


def target_rows(results, solvers, target, wall_key, err_key, evals_key):
    """Per solver: its loosest run within ``target`` and the wall interpolated at ``target``."""
    rows = []
    for label in solvers:
        rs = _of(results, label)
        ok = [r for r in rs if r[err_key] <= target]
        interp = interpolate([(r[err_key], r[wall_key]) for r in rs], target)
        interp_ms = fmt_ms(interp) if interp else "-"
        if ok:
            b = max(ok, key=lambda r: r["tol"])
            rows.append([label, f"{b['tol']:.0e}", f"{b[err_key]:.1e}", fmt_ms(b[wall_key]),
                         b[evals_key], f"{b[wall_key] / b[evals_key] * 1e6:.1f}", interp_ms])
        else:
            rows.append([label, "none in the sweep", "-", "-", "-", "-", interp_ms])
    return rows


def target_tables(report, results, solvers, target, n_samples):
    """The cheapest run within the target error, B then A."""
    report.table(TARGET_HEADER,
                 target_rows(results, solvers, target, "wall_end", "err_own", "evals_end"),
                 caption=f"Cheapest run with max error <= {target:.0e}, "
                 "B (final state only, error on own steps)")
    report.table(TARGET_HEADER, target_rows(results, solvers, target, "wall", "err", "evals"),
                 caption=f"Cheapest run with max error <= {target:.0e}, A ({n_samples} outputs)")


def ratio_rows(results, ours, theirs, tols):
    """Per tolerance: best walls of ``ours`` and ``theirs`` and their ratio, A and B."""
    by = {(r["solver"], r["tol"]): r for r in results}
    rows = []
    for tol in tols:
        a, b = by[ours, tol], by[theirs, tol]
        rows.append([f"{tol:.0e}", fmt_ms(a["wall"]), fmt_ms(b["wall"]),
                     f"{a['wall'] / b['wall']:.2f}", f"{a['err']:.1e} / {b['err']:.1e}",
                     fmt_ms(a["wall_end"]), fmt_ms(b["wall_end"]),
                     f"{a['wall_end'] / b['wall_end']:.2f}",
                     f"{a['err_own']:.1e} / {b['err_own']:.1e}"])
    return rows


def _target_ratio_cells(runs, target, wall_key, err_key, walls_key):
    """Both walls at ``target``, the ratio of the best walls, the median of per-repeat ratios."""
    walls = [interpolate([(r[err_key], r[wall_key]) for r in rs], target) for rs in runs]
    per_repeat = []
    for k in range(min(len(rs[0][walls_key]) for rs in runs)):
        pair = [interpolate([(r[err_key], r[walls_key][k]) for r in rs], target) for rs in runs]
        if all(pair):
            per_repeat.append(pair[0] / pair[1])
    return ([fmt_ms(w) if w else "-" for w in walls]
            + [f"{walls[0] / walls[1]:.2f}" if all(walls) else "-",
               f"{np.median(per_repeat):.2f}" if per_repeat else "-"])


def target_ratio_rows(results, ours, theirs, targets):
    """Per error target: walls interpolated at that max error (log-log) and their ratio, A, B.

    Two ratios: of the best walls, and the median over repeats of each repeat's own ratio
    (one repeat is one interleaved sweep of every tolerance and solver, so load that comes and
    goes within a sweep hits both alike).
    """
    runs = [_of(results, ours), _of(results, theirs)]
    return [[f"{target:.0e}"]
            + _target_ratio_cells(runs, target, "wall", "err", "walls")
            + _target_ratio_cells(runs, target, "wall_end", "err_own", "walls_end")
            for target in targets]


def ratio_tables(report, results, tols, targets, repeats):
    """Ours (angle) against scipy at each tolerance, then at each error target."""
    report.table(["rtol=atol", "A: ours ms", "A: scipy ms", "A: ours/scipy",
                  "A: max err ours / scipy", "B: ours ms", "B: scipy ms", "B: ours/scipy",
                  "B: max err ours / scipy"],
                 ratio_rows(results, OURS, THEIRS, tols),
                 caption=f"{OURS} against {THEIRS} at each tolerance: best of {repeats} "
                         "interleaved repeats (ratio < 1: ours is faster)")
    report.table(["target max error", "A: ours ms", "A: scipy ms", "A: ours/scipy (best)",
                  "A: ours/scipy (median)", "B: ours ms", "B: scipy ms", "B: ours/scipy (best)",
                  "B: ours/scipy (median)"],
                 target_ratio_rows(results, OURS, THEIRS, targets),
                 caption=f"{OURS} against {THEIRS} at each error target, walls interpolated; "
                         f"best: of best walls; median: of the {repeats} sweeps' own ratios "
                         "(\"-\": the sweep does not bracket the target)")


def notes(report, target):
    report.text(
        '- "wall ms interpolated": log(wall) linear in log(error) between the two sweep points '
        f'around {target:.0e} ("-": the sweep does not bracket the target).',
        "- A: both interpolate the sample times with DOP853's 7th-order continuous extension "
        "(ours in the Cayley/angle chart of each step; 3 extra evaluations per step that contains "
        "samples).  B is the integrators' own cost for their accuracy.",
        "- scipy's DOP853 integrates O in R^{2x2}: its orthogonality defect follows the "
        "tolerance; ours keeps O in SO(2) (angles: exactly; Cayley: to round-off) at every "
        "tolerance.",
        "- ours advances the centroids by their exact flow (Prop. 2.1, no evaluations); scipy "
        "integrates them as part of y.",
    )


def draw_work_precision(results, solvers, target, repeats, scene_name, n_samples, plt):
    """Wall against max error (A and B) per solver, and the final orthogonality defect."""
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    curves = (("err_own", "wall_end", "o-", "B: final state only"),
              ("err", "wall", "x:", f"A: {n_samples} outputs"))
    for k, label in enumerate(solvers):
        rs = _of(results, label)
        col = f"C{k}"
        for err_key, wall_key, style, what in curves:
            axes[0].loglog([r[err_key] for r in rs], [r[wall_key] * 1e3 for r in rs], style,
                           color=col, label=f"{label}, {what}")
        axes[1].loglog([r["tol"] for r in rs], [max(r["orth"], 1e-17) for r in rs], "o-",
                       color=col, label=label)
    axes[0].axvline(target, color="r", ls="--", lw=1, label=f"target {target:.0e}")
    axes[0].set_xlabel("max vertex error over time")
    axes[0].set_ylabel(f"wall ms (best of {repeats})")
    axes[0].set_title(f"work-precision, {scene_name}")
    axes[1].set_xlabel("rtol = atol")
    axes[1].set_ylabel("final max |O^T O - I|_F")
    axes[1].set_title("orthogonality defect (Lemma 2.1)")
    for ax in axes:
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    return fig
