"""Work-precision: the whole run's max vertex error against wall time and evaluations.

Solvers, each on the same scene:

  fixed step     every registered integrator that accepts the model (first order: lie_euler,
                 lie_heun, rkmk4, euler_proj, rk4_proj; second order also etd1, etd2,
                 lie_verlet) at h in 0.2 ... 0.005.  A step beyond the method's linear
                 stability limit is refused by the core (StabilityError) and shown so.
  adaptive       ours (DOP853 in Cayley/angle charts, dense output) at tol 1e-3 ... 1e-12.
  scipy          ``solve_ivp`` RK45 and DOP853 at rtol = atol = tol 1e-3 ... 1e-12 on the
                 flattened system (centroids, velocities, d x d matrices, W), the paper's
                 (A-1)/(A-2) written with numpy in mean-field form (see
                 ``benchmarks/core_families/paper_rhs.py``).

Error = max over the sample times (every 0.2 on [0, t_end]) and over all agents i and
vertices a of |x^i_a - x^i_a(ref)|, x^i_a = xbar_i + O_i r_a in absolute coordinates.
The max over the whole run matters: errors in the spread decay like e^{-kappa t}, so an
error taken at t_end only would flatter every method.  All solvers produce the sample
times the way a user gets them: fixed steps land on them, the adaptive solvers
interpolate with their continuous extension (its extra evaluations are counted).

Reference: ours adaptive at tol 1e-13, cross-checked against rkmk4 at dt = 1e-3; their
agreement is the floor below which errors are not resolved.

Cases: first- and second-order models, d = 2 and 3, initial rotation diameter D0 < 1
(rotations within 0.3 rad of a common one; Prop. 2.2 ii applies) and D0 > 1 (uniform
rotations), N = 10, t_end = 20; plus two extra cases: stiff damping (m = 0.01) and d = 4.
Wall times are the best (and median) of interleaved repeats: a burst of load on the
machine hits every solver alike.
"""

from dataclasses import dataclass

NAME = "precision"
HELP = ("work-precision: max vertex error over the run vs wall time and evaluations, "
        "all integrators and scipy")

STEPS = [0.2, 0.1, 0.05, 0.02, 0.01, 0.005]
TOLERANCES = [10.0 ** -k for k in range(3, 13)]
TARGETS = [1e-4, 1e-6, 1e-8]

# id -> (label, model order, d, rotations, mass)
CASES = {
    "o1-d2-near": ("1st order, d = 2, D0 < 1", 1, 2, {"within": 0.3}, None),
    "o1-d2-far": ("1st order, d = 2, D0 > 1", 1, 2, "uniform", None),
    "o1-d3-near": ("1st order, d = 3, D0 < 1", 1, 3, {"within": 0.3}, None),
    "o1-d3-far": ("1st order, d = 3, D0 > 1", 1, 3, "uniform", None),
    "o2-d2-near": ("2nd order, d = 2, D0 < 1", 2, 2, {"within": 0.3}, 0.5),
    "o2-d2-far": ("2nd order, d = 2, D0 > 1", 2, 2, "uniform", 0.5),
    "o2-d3-near": ("2nd order, d = 3, D0 < 1", 2, 3, {"within": 0.3}, 0.5),
    "o2-d3-far": ("2nd order, d = 3, D0 > 1", 2, 3, "uniform", 0.5),
    "o2-d2-stiff": ("2nd order, d = 2, stiff m = 0.01, D0 < 1", 2, 2, {"within": 0.3}, 0.01),
    "o1-d4-near": ("1st order, d = 4, D0 < 1", 1, 4, {"within": 0.3}, None),
}
QUICK_CASES = ["o1-d2-near", "o2-d3-far"]


def add_arguments(p):
    from ..options import at_least, float_list
    p.add_argument("--cases", default=",".join(CASES),
                   help="comma-separated case ids (default: all): " + ", ".join(CASES))
    p.add_argument("--steps", type=float_list(1e-300), default=STEPS,
                   help="fixed step sizes h; each must divide --sample-every "
                        "(default 0.2,0.1,...,0.005)")
    p.add_argument("--tolerances", type=float_list(1e-300), default=TOLERANCES,
                   help="tolerances of ours and scipy's (default 1e-3,...,1e-12)")
    p.add_argument("--targets", type=float_list(1e-300), default=TARGETS,
                   help="target errors of the frontier table (default 1e-4,1e-6,1e-8)")
    p.add_argument("--n", type=at_least(2), default=10, help="agents per case (default 10)")
    p.add_argument("--t-end", type=at_least(1e-300, float),
                   default=20.0, help="time span (default 20)")
    p.add_argument("--sample-every", type=at_least(1e-300, float), default=0.2,
                   help="spacing of the sample times the error is taken at (default 0.2)")
    p.add_argument("--ref-tol", type=at_least(1e-300, float), default=1e-13,
                   help="tolerance of the adaptive reference (default 1e-13)")
    p.add_argument("--ref-dt", type=at_least(1e-300, float), default=1e-3,
                   help="step of the rkmk4 cross-check of the reference (default 1e-3)")
    p.add_argument("--seed", type=at_least(0), default=1, help="scene seed (default 1)")


# -- scenes -----------------------------------------------------------------------------------

def case_scene(case, n, t_end, every, seed):
    from polymatch_ros.core import load_scene
    _label, order, dim, rotations, mass = CASES[case]
    model = {"order": order, "kappa": 1.0, "gamma": 1.0}
    group = {"name": "polytopes", "shape": {"simplex": dim}, "count": n,
             "centroids": {"box": [-5.0, 5.0]}, "rotations": rotations}
    if order == 2:
        model["mass"] = mass
        group["velocities"] = {"centroid": {"normal": 0.5}, "angular": {"normal": 0.5}}
    return load_scene({"name": case, "dimension": dim, "seed": seed, "model": model,
                       "groups": [group], "time": {"t_end": t_end, "samples": {"every": every}}})


def rotation_diameter(scene):
    from polymatch_ros.core.metrics import point_set_diameter
    gs = scene.initial.groups[0]
    return point_set_diameter(scene.model.rotations.flat(gs.rot))


# -- errors -----------------------------------------------------------------------------------

def vertex_error(out, ref_verts, reference):
    """max over samples, agents and vertices of |x^i_a - x^i_a(ref)| (Euclidean)."""
    import numpy as np

    from polymatch_ros.core.metrics import vertices
    diff = vertices(out.centroids, out.mats, reference) - ref_verts
    return float(np.sqrt(np.max(np.sum(diff * diff, axis=-1))))


def _score(cells, times, ref_verts, reference):
    """Error, orthogonality defect and counts of every cell from its first run."""
    import numpy as np

    from polymatch_ros.core.metrics import orthogonality
    for cell in cells:
        if not cell.ok:
            continue
        t = np.asarray(cell.out.times)
        if len(t) != len(times) or np.max(np.abs(t - times)) > 1e-9 * max(1.0, times[-1]):
            cell.status = "failed: output times differ from the sample times"
            continue
        cell.err = vertex_error(cell.out, ref_verts, reference)
        cell.orth = orthogonality(cell.out.mats)


# -- the benchmark ----------------------------------------------------------------------------

def _check_grid(steps, every, t_end):
    from polymatch_ros.core import PolymatchError
    for h in steps:
        k = every / h
        if abs(k - round(k)) > 1e-9 * k:
            raise PolymatchError(f"precision: step {h:g} does not divide the sample "
                                 f"spacing {every:g}; the error is taken at the sample times, "
                                 "which every step grid must contain")
    k = t_end / every
    if abs(k - round(k)) > 1e-9 * k:
        raise PolymatchError(
            f"precision: the sample spacing {every:g} must divide t_end = {t_end:g}")


@dataclass(frozen=True)
class _Settings:
    """What every case of a run shares."""

    cases: list
    steps: list
    tols: list
    n: int
    t_end: float
    every: float
    ref_tol: float
    ref_dt: float
    seed: int
    repeats: int
    targets: list


def _settings(args):
    """The run's settings (--quick: two small cases); unknown cases and step grids that miss
    the sample times are refused."""
    from polymatch_ros.core import PolymatchError

    if args.quick:
        cases, steps, tols = QUICK_CASES, [0.1, 0.05], [1e-4, 1e-6]
        n, t_end, every, ref_tol, ref_dt = 6, 1.0, 0.2, 1e-11, 0.01
    else:
        cases = [c.strip() for c in args.cases.split(",") if c.strip()]
        steps, tols = sorted(args.steps, reverse=True), sorted(args.tolerances, reverse=True)
        n, t_end, every = args.n, args.t_end, args.sample_every
        ref_tol, ref_dt = args.ref_tol, args.ref_dt
    unknown = [c for c in cases if c not in CASES]
    if unknown:
        raise PolymatchError(
            f"precision: unknown case {unknown[0]!r}; known: {', '.join(CASES)}")
    _check_grid(list(steps) + [ref_dt], every, t_end)
    return _Settings(cases, steps, tols, n, t_end, every, ref_tol, ref_dt, args.seed,
                     args.repeats or (1 if args.quick else 3), sorted(args.targets, reverse=True))


def _intro(report, s):
    report.text(
        f"N = {s.n} congruent regular d-simplices, kappa = gamma = 1 (second order: m as "
        f"stated, centroid and angular velocities ~ N(0, 0.5^2)), t_end = {s.t_end:g}.  Error = "
        f"max over {int(round(s.t_end / s.every)) + 1} sample times (every {s.every:g}) and all "
        f"vertices of |x^i_a - x^i_a(ref)| (Euclidean, absolute coordinates).  Wall = the whole "
        f"`simulate` / `solve_ivp` call producing those samples, best (and median) of "
        f"{s.repeats} repeats interleaved over every cell of a case.  evals = right-hand-side "
        f"evaluations (adaptive solvers: including the 3 per step that dense output costs).  "
        f"orth. defect = max over samples and agents of |O_i^T O_i - I|_F.")


@dataclass
class _Case:
    """One case measured: its scene, the reference, the rkmk4 gap to it and every cell."""

    case: str
    scene: object
    d0: float
    ref: object
    gap: float
    cells: list

    @property
    def label(self):
        return CASES[self.case][0]


def _measure_case(case, s, log):
    """References, then every solver's cells round-robin, scored against the reference."""
    import numpy as np

    from polymatch_ros.core.metrics import vertices

    from .solve import Solver, measure, solve, solvers_for

    label = CASES[case][0]
    scene = case_scene(case, s.n, s.t_end, s.every, s.seed)
    times = np.asarray(scene.samples, dtype=float)
    reference = scene.model.groups[0].reference
    d0 = rotation_diameter(scene)
    log(f"precision: {case} ({label}, D0 = {d0:.2f}): references")
    ref = solve(scene, Solver("adaptive", "adaptive", s.ref_tol), times)
    ref_verts = vertices(ref.centroids, ref.mats, reference)
    check = solve(scene, Solver("rkmk4", "fixed", s.ref_dt), times)
    gap = vertex_error(check, ref_verts, reference)
    cells = solvers_for(scene.model.order, s.steps, s.tols)
    log(f"precision: {case}: {len(cells)} cells x {s.repeats} interleaved repeats")
    measure(cells, scene, times, s.repeats, lambda text: log(f"precision:   {text}"),
            warmup=True)
    _score(cells, times, ref_verts, reference)
    return _Case(case, scene, d0, ref, gap, cells)


def _case_section(report, c, s):
    """The case's heading, its every-solver table, its order table and figure; returns the
    order rows."""

    m = c.scene.model
    params = f"m = {m.mass:g}, " if m.order == 2 else ""
    report.text(f"### {c.label}  (`{c.case}`)",
                "",
                f"d = {m.dim}, N = {m.n_agents}, {params}D0 = max_ij |O_i - O_j|_F = "
                f"{c.d0:.3f} at t = 0.  Reference: ours adaptive at tol {s.ref_tol:g} "
                f"({c.ref.steps} steps); rkmk4 at dt = {s.ref_dt:g} agrees with it to "
                f"{c.gap:.1e} (max vertex distance over the samples): errors near that floor are "
                f"not resolved.")
    header, rows = case_table(c.cells, s.repeats)
    report.table(header, rows, caption=f"{c.label}: every solver")
    orows = order_rows(c.cells, c.gap)
    report.table(["method", "nominal order",
                  "observed order (consecutive h, errors > 100 x floor)", "note"],
                 orows,
                 caption=f"{c.label}: observed convergence order of the fixed-step methods")
    report.figure(c.case, error_figure(c.label, c.cells, s.targets, s.repeats),
                  f"{c.label}: error vs wall time and evaluations")
    return orows


def _problems(case, cells):
    """A summary line of the case's refused and failed cells, if any."""
    refused = sorted(
        {f"{c.name} h = {c.value:g}" for c in cells if c.status.startswith("refused")})
    failed = sorted(
        {f"{c.name} {c.param}: {c.status}" for c in cells if c.status.startswith("failed")})
    if refused or failed:
        return [f"- `{case}`: " + "; ".join(
            ([f"refused (unstable): {', '.join(refused)}"] if refused else []) + failed)]
    return []


def _frontier_section(report, frontier, orders, summary):
    report.text("### Frontier")
    report.table(["case", "target", "cheapest (best wall)", "best / median ms", "evals",
                  "runner-up (other method)", "cheapest scipy", "cheapest fixed step",
                  "fewest evals"], frontier,
                 caption="Cheapest run meeting each target error (wall time: best of the "
                         "interleaved repeats). Fixed steps are what a distributed "
                         "(ROS lockstep) ensemble can run.")
    notes = ["- Fixed-step Lie methods (lie_*, rkmk4, etd*, lie_verlet) keep O_i in SO(d) by "
             "construction: their orth. defect is round-off.  The projection baselines re-project "
             "every step; scipy integrates O in R^{d x d} and its defect follows its tolerance.",
             "- Decoupled centroids follow their exact flow (Prop. 2.1) in every core method, "
             "so a core method's error is its rotations' error; scipy integrates the centroids "
             "too."]
    if summary:
        notes += ["- Refusals and failures:"] + summary
    if orders:
        notes.append("- Observed order below nominal: "
                     + "; ".join(f"{r[0]} {r[1]} ({r[3]})" for r in orders))
    report.text(*notes)


def run(args, log):
    from ..report import Report

    report = Report(NAME, "Work-precision (`python -m benchmarks precision`)")
    s = _settings(args)
    _intro(report, s)
    frontier, orders, summary = [], [], []
    for case in s.cases:
        c = _measure_case(case, s, log)
        orows = _case_section(report, c, s)
        orders += [[case] + r for r in orows if r[3] == "below nominal"]
        frontier += frontier_rows(case, c.cells, s.targets)
        summary += _problems(case, c.cells)
    _frontier_section(report, frontier, orders, summary)
    return report


# -- tables and figures from the scored cells -----------------------------------------------

def _fmt_err(e):
    return f"{e:.2e}"


def case_table(cells, repeats):
    from ..timing import fmt_ms
    rows = []
    for c in cells:
        if not c.ok:
            rows.append([c.name, c.param, c.status, "-", "-", "-", "-"])
            continue
        rows.append([c.name, c.param, _fmt_err(c.err), fmt_ms(c.best), fmt_ms(c.median),
                     c.out.evals, f"{c.orth:.1e}"])
    header = ["method", "h or tol", "max error", f"wall ms (best of {repeats})", "median ms",
              "rhs evals", "orth. defect"]
    return header, rows


def order_rows(cells, floor):
    """Observed convergence order of every fixed-step method from consecutive step sizes."""
    import math

    from polymatch_ros.core import METHODS
    rows = []
    for name in dict.fromkeys(c.name for c in cells if c.kind == "fixed"):
        pts = sorted(((c.value, c.err) for c in cells if c.name == name and c.ok), reverse=True)
        slopes = []
        for (h1, e1), (h2, e2) in zip(pts, pts[1:]):
            if e2 > 100 * floor and e1 > e2:
                slopes.append(math.log(e1 / e2) / math.log(h1 / h2))
        nominal = METHODS[name].info.order
        note = ""
        if slopes and slopes[-1] < nominal - 0.5:
            note = "below nominal"
        elif not slopes:
            note = "not resolved (errors at the reference floor or refused)"
        rows.append([name, nominal, ", ".join(f"{s:.2f}" for s in slopes) or "-", note])
    return rows


def frontier_rows(label, cells, targets):
    from ..timing import fmt_ms

    def name(c):
        return f"{c.name} {c.param}"

    rows = []
    for target in targets:
        ok = sorted((c for c in cells if c.ok and c.err <= target), key=lambda c: c.best)
        if not ok:
            rows.append([label, f"{target:.0e}", "none", "-", "-", "-", "-", "-", "-"])
            continue
        win = ok[0]
        second = next((c for c in ok if c.name != win.name), None)
        scipy = next((c for c in ok if c.kind == "scipy"), None)
        fixed = next((c for c in ok if c.kind == "fixed"), None)
        fewest = min(ok, key=lambda c: c.out.evals)
        rows.append([label, f"{target:.0e}", name(win),
                     f"{fmt_ms(win.best)} / {fmt_ms(win.median)}", win.out.evals,
                     f"{name(second)} ({fmt_ms(second.best)})" if second else "-",
                     f"{name(scipy)} ({fmt_ms(scipy.best)})" if scipy else "none",
                     f"{name(fixed)} ({fmt_ms(fixed.best)})" if fixed else "none",
                     f"{name(fewest)} ({fewest.out.evals})"])
    return rows


def error_figure(label, cells, targets, repeats):
    """Max error against wall time and against evaluations, every solver of a case."""
    def draw(plt):
        fig, axes = plt.subplots(1, 2, figsize=(12, 4.6), sharey=True)
        solvers = list(dict.fromkeys(c.name for c in cells))
        for k, solver in enumerate(solvers):
            cs = [c for c in cells if c.name == solver and c.ok and c.err > 0]
            if not cs:
                continue
            kind = cs[0].kind
            style = {"fixed": "o-", "adaptive": "D-", "scipy": "x:"}[kind]
            if kind == "fixed" and solver.endswith("_proj"):
                style = "s--"
            col = "k" if kind == "adaptive" else f"C{k % 10}"
            err = [c.err for c in cs]
            axes[0].loglog([c.best * 1e3 for c in cs], err, style, color=col, label=solver, ms=4)
            axes[1].loglog([c.out.evals for c in cs], err, style, color=col, label=solver, ms=4)
        for ax in axes:
            for t in targets:
                ax.axhline(t, color="r", lw=0.6, ls="--")
            ax.grid(True, which="both", alpha=0.3)
        axes[0].set_xlabel(f"wall ms (best of {repeats})")
        axes[1].set_xlabel("right-hand-side evaluations")
        axes[0].set_ylabel("max vertex error over the run")
        axes[0].set_title(f"{label}: error vs wall time")
        axes[1].set_title("error vs evaluations")
        axes[1].legend(fontsize=7, loc="best")
        return fig
    return draw
