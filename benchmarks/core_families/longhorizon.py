"""Long horizons: orthogonality defect and energy drift after 10^5 steps.

Every registered fixed-step integrator runs 10^5 steps of dt = 0.05 (t = 5000) on a
small ensemble (N = 4 regular tetrahedra in R^3, uniform rotations), and scipy's
``solve_ivp`` RK45 and DOP853 (rtol = atol = tol, on the flattened system of
``benchmarks/core_families/paper_rhs.py``) and ours adaptive run over the same time span.

  A  second-order model (A-1) with gamma = 0 (undamped; m = kappa = 1, random centroid and
     angular velocities).  By Proposition 2.2 (i) the energy
         E = (m/N) sum_i |W_i|_F^2 + (kappa/N) sum_i |O_i - Obar|_F^2
     is conserved.  Reported: the relative drift |E(t) - E(0)| / E(0) (running max up to
     t = 10^k steps), its growth exponent over the last decade (drift ~ t^p: p ~ 0 bounded,
     p ~ 1 secular) and the orthogonality defect max_i |O_i^T O_i - I|_F.
  B  first-order model (A-2) (kappa = gamma = 1): the orthogonality defect only.

Fixed steps beyond a method's linear stability limit are refused by the core
(StabilityError): with gamma = 0 the undamped oscillation rules out every method
whose stability region misses the imaginary axis (Euler, Heun, ETD1).  E is computed
from the matrices as they are, without projecting them onto SO(d).
"""

from dataclasses import dataclass

NAME = "longhorizon"
HELP = ("orthogonality defect and energy drift (gamma = 0) after 10^5 steps, "
        "every integrator and scipy")


def add_arguments(p):
    from ..options import add_number, float_list
    add_number(p, "--steps", 10, 100_000, "fixed steps per run")
    add_number(p, "--dt", 1e-300, 0.05, "fixed step", float)
    add_number(p, "--n", 2, 4, "agents")
    add_number(p, "--dim", 2, 3, "dimension")
    p.add_argument("--tolerances", type=float_list(1e-300), default=[1e-6, 1e-9],
                   help="rtol = atol of scipy RK45/DOP853 and ours adaptive (default 1e-6,1e-9)")
    add_number(p, "--seed", 0, 1, "scene seed")


def _scene(order, n, dim, t_end, seed):
    from polymatch_ros.core import load_scene
    model = {"order": order, "kappa": 1.0, "gamma": 0.0 if order == 2 else 1.0}
    group = {"name": "polytopes", "shape": {"simplex": dim}, "count": n,
             "centroids": {"box": [-5.0, 5.0]}, "rotations": "uniform"}
    if order == 2:
        model["mass"] = 1.0
        group["velocities"] = {"centroid": {"normal": 0.5}, "angular": {"normal": 0.5}}
    return load_scene({"name": f"longhorizon_order{order}", "dimension": dim, "seed": seed,
                       "model": model, "groups": [group], "time": {"t_end": t_end}})


def _checkpoints(steps):
    """10^2, 10^3, ... up to ``steps`` (and ``steps`` itself)."""
    out, k = [], 10
    while k < steps:
        if k >= 100 or steps < 1000:
            out.append(k)
        k *= 10
    return out + [steps]


def _sample_steps(steps, linear=5001):
    """Step indices of the samples: log-spaced (early times), ``linear`` evenly spaced, and the
    checkpoints."""
    import numpy as np
    idx = np.concatenate([np.round(np.logspace(0, np.log10(steps), 81)),
                          np.round(np.linspace(0, steps, min(linear, steps + 1))),
                          _checkpoints(steps)])
    return np.unique(idx.astype(int))


def _defect_series(mats):
    """max_i |O_i^T O_i - I|_F at each sample (Lemma 2.1)."""
    import numpy as np

    from polymatch_ros.core.metrics import orthogonality
    return np.array([orthogonality(m) for m in mats])


def _running_max_at(t, series, marks):
    import numpy as np
    return [float(np.max(series[t <= m * (1 + 1e-12)])) for m in marks]


def _growth(t, series, marks):
    """Exponent p of series ~ t^p from its max over the last two decade windows.

    Windows (T/100, T/10] and (T/10, T], T = the last mark: a bounded oscillation has about
    the same max in both (p ~ 0), a secular drift grows with t (p ~ 1 for a linear one).
    Windowed maxima, not running maxima, so an early peak cannot hide a later drift.
    None when not measurable.
    """
    import math

    import numpy as np
    if len(marks) < 2:
        return None
    hi, mid = marks[-1], marks[-1] / 10
    last = series[(t > mid) & (t <= hi * (1 + 1e-12))]
    prev = series[(t > mid / 10) & (t <= mid * (1 + 1e-12))]
    if not len(last) or not len(prev) or np.max(prev) <= 0 or np.max(last) <= 0:
        return None
    return math.log10(float(np.max(last)) / float(np.max(prev)))


def _verdict(drift_end, p):
    if drift_end < 1e-12:
        return "round-off"
    if p is None:
        return "-"
    if p < 0.2:
        return "bounded"
    return f"grows ~ t^{p:.1f}" + (" (secular)" if p >= 0.7 else "")


def _wall_cells(run):
    """Best and median wall seconds of a solver's runs ('-' if none ran)."""
    if not run.walls:
        return ["-", "-"]
    return [f"{run.best:.2f}", f"{run.median:.2f}"]


RUN_HEADER = ["method", "h or tol", "wall s (best)", "median s", "rhs evals"]


def _rows(runs, scored, width):
    """A row per solver: ``scored(run)`` for one that ran, its status and ``width`` dashes for
    one that was refused or failed."""
    return [scored(r) if r.ok else [r.name, r.param, r.status] + ["-"] * width for r in runs]


def _second_order(runs, flat, marks):
    """Rows of table A: energy drift (Prop. 2.2 i), its growth and the orthogonality defect;
    keeps each run's (t, drift, defect) in ``run.series`` for the figure."""
    import numpy as np

    def scored(r):
        t = r.out.times
        e = flat.energy(r.out.mats, r.out.w)
        drift = np.abs(e - e[0]) / e[0]
        dm = _running_max_at(t, drift, marks)
        p = _growth(t, drift, marks)
        defect = _defect_series(r.out.mats)
        r.series = (t, drift, defect)
        return ([r.name, r.param] + _wall_cells(r) + [r.out.evals] + [f"{v:.1e}" for v in dm]
                + ["-" if p is None else f"{p:.2f}", _verdict(dm[-1], p), f"{defect.max():.1e}"])

    return _rows(runs, scored, len(marks) + 5)


def _first_order(runs, marks):
    """Rows of table B: the orthogonality defect (Lemma 2.1); ``run.series`` = (t, None,
    defect)."""
    def scored(r):
        t = r.out.times
        defect = _defect_series(r.out.mats)
        r.series = (t, None, defect)
        return ([r.name, r.param] + _wall_cells(r) + [r.out.evals]
                + [f"{v:.1e}" for v in _running_max_at(t, defect, marks)])

    return _rows(runs, scored, len(marks) + 2)


def _intro(report, span):
    s = span
    report.text(f"N = {s.n} regular {s.dim}-simplices in R^{s.dim}, uniform rotations, "
                f"{s.steps:,} steps of dt = {s.dt:g} (t = {s.steps * s.dt:g}); scipy and ours "
                f"adaptive over the same span at rtol = atol = "
                f"{', '.join(f'{t:.0e}' for t in s.tols)}.  Quantities are evaluated at "
                f"{len(s.times)} sample times (log- and linearly spaced); \"up to 10^k\" = "
                f"running max over t <= 10^k dt.  Wall: seconds for the whole run, best / median "
                f"of {s.repeats} (runs interleaved across solvers).")


def _mark_labels(marks_steps):
    """'10^3' for a power of ten, '2,500' otherwise."""
    import numpy as np

    return [f"10^{int(round(np.log10(k)))}" if 10 ** int(round(np.log10(k))) == k
            else f"{k:,}" for k in marks_steps]


def _drift_figure(runs_a, runs_b):
    def draw(plt):
        import numpy as np

        fig, axes = plt.subplots(1, 3, figsize=(16, 4.4))
        panels = [(axes[0], runs_a, 1), (axes[1], runs_a, 2), (axes[2], runs_b, 2)]
        for ax, runs_, which in panels:
            for k, r in enumerate(runs_):
                t, series = r.series[0], r.series[which]
                style = "x:" if r.kind == "scipy" else ("D-" if r.kind == "adaptive" else "-")
                sel = t > 0
                ax.loglog(t[sel], np.maximum(series[sel], 1e-17), style, color=f"C{k % 10}",
                          ms=3, lw=1, label=f"{r.name} {r.param}")
        axes[0].set_title("A: gamma = 0, |E(t) - E(0)| / E(0)")
        axes[1].set_title("A: gamma = 0, orthogonality defect")
        axes[2].set_title("B: first order, orthogonality defect")
        for ax in axes:
            ax.set_xlabel("t")
            ax.grid(True, which="both", alpha=0.3)
            ax.legend(fontsize=6)
        return fig
    return draw


NOTES = ("- Lie methods (lie_*, rkmk4, etd*, lie_verlet, adaptive) stay on SO(d) by "
         "construction: their defect is accumulated round-off.  Projection baselines "
         "re-project every step.  scipy's O drifts off SO(d) at a rate set by its "
         "tolerance, and E is measured on those matrices.",
         "- growth p: log10 of (max drift over the last decade of t) / (max over the "
         "decade before); \"bounded\": p < 0.2 (an oscillation that does not grow); "
         "\"secular\": p >= 0.7 (about linear growth in t, p = 1).")


@dataclass(frozen=True)
class _Span:
    """The long horizon every solver runs: ``steps`` of ``dt``, sampled at ``times``."""

    dt: float
    steps: int
    times: object
    tols: list
    n: int
    dim: int
    seed: int
    repeats: int

    @property
    def marks_steps(self):
        return _checkpoints(self.steps)

    @property
    def marks(self):
        return [k * self.dt for k in self.marks_steps]

    def measure(self, order, log):
        """Every solver for the model of ``order`` over the span: (scene, solvers, flat)."""
        from .solve import measure, solvers_for

        scene = _scene(order, self.n, self.dim, self.steps * self.dt, self.seed)
        runs = solvers_for(order, [self.dt], self.tols)
        flat = measure(runs, scene, self.times, self.repeats,
                       lambda text: log(f"longhorizon: {text}"))
        return scene, runs, flat


def _section_a(report, span, log):
    """A: second order, gamma = 0; returns the runs that ran."""
    scene, runs, flat = span.measure(2, log)
    rows = _second_order(runs, flat, span.marks)
    u0 = flat.unpack(flat.initial(scene))
    report.text("### A. Second-order model (A-1), gamma = 0: energy (Prop. 2.2 i) "
                "and orthogonality",
                "", f"m = kappa = 1, gamma = 0, E(0) = {flat.energy(u0['rot'], u0['w']):.4f}.")
    report.table(RUN_HEADER
                 + [f"rel. energy drift up to {lab}" for lab in _mark_labels(span.marks_steps)]
                 + ["growth p (decade windows)", "verdict", "orth. defect (max)"], rows,
                 caption="gamma = 0: relative energy drift |E(t) - E(0)| / E(0), running max")
    return [r for r in runs if r.ok]


def _section_b(report, span, log):
    """B: first order; returns the runs that ran."""
    _scene1, runs, _flat = span.measure(1, log)
    rows = _first_order(runs, span.marks)
    report.text("### B. First-order model (A-2): orthogonality defect")
    report.table(RUN_HEADER
                 + [f"orth. defect up to {lab}" for lab in _mark_labels(span.marks_steps)],
                 rows,
                 caption="first order: max_i |O_i^T O_i - I|_F, running max")
    return [r for r in runs if r.ok]


def run(args, log):
    from ..report import Report

    report = Report(NAME, "Long horizons (`python -m benchmarks longhorizon`)")
    steps = 1000 if args.quick else args.steps
    tols = [1e-6] if args.quick else sorted(args.tolerances, reverse=True)
    # quick: angles, the cheapest steps
    dt, n, dim = args.dt, args.n, (2 if args.quick else args.dim)
    repeats = args.repeats or 1
    span = _Span(dt, steps, _sample_steps(steps) * dt, tols, n, dim, args.seed, repeats)
    _intro(report, span)
    runs_a = _section_a(report, span, log)
    runs_b = _section_b(report, span, log)
    report.text(*NOTES)
    report.figure("drift", _drift_figure(runs_a, runs_b),
                  "energy drift and orthogonality defect over the long horizon")
    return report
