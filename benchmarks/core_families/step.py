"""Wall time of ONE integrator step of the whole ensemble.

One step of ``rkmk4`` (Runge-Kutta-Munthe-Kaas, classical RK4 tableau) makes
four model evaluations.  Each is the mean field S = sum_k O_k and the
rotation rate of the paper's models,

    (A-2)  W_i = kappa/(2 gamma N) (S O_i^T - O_i S^T)          (first order, O_i' = W_i O_i)
    (A-1)  m W_i' = -gamma W_i + kappa/(2N) (S O_i^T - O_i S^T)  (second order)

(the sum over k of (O_k O_i^T - O_i O_k^T) collapses to S: O(N d^3), see
`python -m benchmarks meanfield`), and the stage rotations psi(Theta) O_n with psi
the Cayley map or exp, so every O_i stays in SO(d) (Lemma 2.1).  Centroids
follow the exact linear flow of Proposition 2.1 and cost O(N d) per step.

Representations compared at d = 3: "so3" (default: 3x3 matrices in
structure-of-arrays layout, Cayley map in closed form), "so3-exp" (same
layout, Rodrigues' exp) and "matrix" (N x d x d arrays, the representation
used for d >= 4: for d = 4 so(4) = so(3) + so(3) held as six length-N rows and the
Cayley map through quaternion pairs, by batched matrix products otherwise).  A table
times d = 3, 4, 10 side by side at one N and reports each cost against the previous d's.
``lie_euler`` (1 evaluation) and ``rk4_proj`` (classical RK4 in R^{dxd} + polar projection)
are shown for comparison.  Each repeat starts from a fresh copy of the
initial state, so no cached mean field is reused.
"""

NAME = "step"
HELP = "wall time of one rkmk4 step (N = 10,000, d = 3) and a table over N and d"

TARGET_SECONDS = 4e-3       # the target: one rkmk4 step at N = 10,000, d = 3


def add_arguments(p):
    from ..options import at_least, int_list
    p.add_argument("--n", type=at_least(1), default=10_000,
                   help="agents for the headline table (default 10000)")
    p.add_argument("--dim", type=at_least(2), default=3,
                   help="dimension for the headline table (default 3)")
    p.add_argument("--sizes", type=int_list(1), default=[10, 100, 1000, 10_000, 100_000],
                   help="N values of the N x d table (default 10,100,1000,10000,100000)")
    p.add_argument("--dims", type=int_list(2), default=[2, 3, 4, 6, 10],
                   help="d values of the N x d table (default 2,3,4,6,10)")
    p.add_argument("--grid-order", type=int, choices=(1, 2),
                   default=1, help="model order of the N x d table")
    p.add_argument("--max-step-seconds", type=at_least(0.0, float), default=1.5,
                   help="skip N x d cells whose step is predicted to take longer (default 1.5)")
    p.add_argument("--dt", type=at_least(1e-300, float), default=0.05,
                   help="step size (does not change the cost)")
    p.add_argument("--ratio-dims", type=int_list(2), default=[3, 4, 10],
                   help="d values timed side by side at --n for the cost ratios between "
                        "dimensions (default 3,4,10)")



MODEL_LABELS = {1: "1st (A-2)", 2: "2nd (A-1)"}
ORDER_WORDS = {1: "first", 2: "second"}
COLD_CACHE_NOTE = (
    '- "One step" rows are interleaved with the other configurations, whose arrays evict this '
    "one's from the CPU caches between repeats: a cold-cache step. The consecutive-step column "
    "and the N x d grid below (one configuration at a time) time the warm step of a running "
    "simulation.")


def _stepper(meth, scene, dt):
    """(fn, setup) timing one ``drive`` from a fresh State (no cached coupling)."""
    from polymatch_ros.core import State, System, drive
    system = System(scene.model)
    groups = scene.initial.groups
    return (lambda st: drive(meth, system, st, dt)), (lambda: State(0.0, groups))


def _consecutive(meth, scene, dt, steps, repeats):
    """Seconds per step over ``steps`` consecutive steps of an evolving state (as in a run)."""
    from polymatch_ros.core import State, System, drive

    from ..timing import measure
    system = System(scene.model)

    def chain(_):
        st = State(0.0, scene.initial.groups)
        for _k in range(steps):
            st = drive(meth, system, st, dt)

    return measure(chain, repeats).scaled(1.0 / steps)


def _prepare(scene, meth):
    """Projection baselines need matrices where the default representation is angles (d = 2)."""
    from polymatch_ros.core import with_representation
    if meth.info.family == "projection" and scene.model.rotations.name == "angle":
        return with_representation(scene, "matrix")
    return scene


# -- the headline: every method and representation at one N and d -----------------------------


def _configurations(n, dim, dt):
    """Every model order (A-2, A-1) x representation x method at (n, dim), each with its
    stepper; "default" marks the representation a scene gets unless told otherwise."""
    from polymatch_ros.core import METHODS

    from ..scenes import representation_label, timing_scene

    reps = ["auto", "so3-exp", "matrix"] if dim == 3 else ["auto", "matrix"]
    configs = []
    for order in (1, 2):
        for rep in reps:
            base = timing_scene(n, dim, order, rep)
            for name in ("rkmk4", "lie_euler", "rk4_proj"):
                meth = METHODS[name]
                scene = _prepare(base, meth)
                fn, setup = _stepper(meth, scene, dt)
                configs.append({"order": order, "rep": representation_label(scene.model.rotations),
                                "default": rep == "auto" and scene is base, "method": name,
                                "stages": meth.info.stages, "fn": fn, "setup": setup})
    return configs


def _default_rkmk4(configs, order):
    return next(c for c in configs
                if c["order"] == order and c["default"] and c["method"] == "rkmk4")


def _one_step_table(report, configs, n, dim, repeats):
    """Best/median/max of one step of every configuration, timed interleaved."""
    from ..timing import fmt_ms

    rows = [[MODEL_LABELS[c["order"]], c["rep"] + (" *default*" if c["default"] else ""),
             c["method"], c["stages"], fmt_ms(c["timing"].best), fmt_ms(c["timing"].median),
             fmt_ms(c["timing"].worst), f"{c['timing'].best / c['stages'] * 1e3:.3f}"]
            for c in configs]
    report.table(["model", "representation", "method", "evals/step", "best ms", "median ms",
                  "max ms", "best ms/eval"], rows,
                 caption=f"One step, N = {n:,}, d = {dim}, {repeats} interleaved repeats each")


def _target_verdict(one_step, run_t, chain):
    """'best: met, median: NOT met, 50-step run: met' against the < 4 ms target."""
    return ", ".join(f"{name}: {'met' if v < TARGET_SECONDS else 'NOT met'}"
                     for name, v in (("best", one_step.best), ("median", one_step.median),
                                     (f"{chain}-step run", run_t.best)))


def _rkmk4_table(args, log, report, configs, n, dim):
    """The default rkmk4 per model order: its interleaved one-step timing beside the warm step
    of a run of consecutive steps (and, at N = 10,000, d = 3, whether the target is met)."""
    from polymatch_ros.core import METHODS

    from ..scenes import timing_scene
    from ..timing import fmt_ms

    chain = 3 if args.quick else 50
    runs = 1 if args.quick else 5
    at_target = n == 10_000 and dim == 3
    rows = []
    for order in (1, 2):
        main = _default_rkmk4(configs, order)
        t = main["timing"]
        log(f"step: rkmk4, order {order}: {runs} runs of {chain} consecutive steps")
        run_t = _consecutive(METHODS["rkmk4"], timing_scene(n, dim, order), args.dt, chain, runs)
        rows.append([f"{ORDER_WORDS[order]} order, {main['rep']}", fmt_ms(t.best),
                     fmt_ms(t.median), f"{100 * t.spread:.0f}%", fmt_ms(run_t.best),
                     fmt_ms(run_t.median)]
                    + ([_target_verdict(t, run_t, chain)] if at_target else []))
    header = ["rkmk4", "one step: best ms", "median ms", "spread (max/best - 1)",
              f"ms/step in a {chain}-step run (best of {runs})", "median"]
    if at_target:
        header.append(f"target < {TARGET_SECONDS * 1e3:g} ms")
    report.table(header, rows, caption=f"rkmk4 at N = {n:,}, d = {dim}"
                 + ("" if at_target else " (the < 4 ms target is stated for N = 10,000, d = 3)"))


def _headline_notes(configs, dim):
    """rkmk4 in each other representation against the default (d = 3), then the caveats."""
    lines = []
    if dim == 3:
        for order in (1, 2):
            best = _default_rkmk4(configs, order)["timing"].best
            lines += [f"- {ORDER_WORDS[order]} order: rkmk4 in {c['rep']} takes "
                      f"{c['timing'].best / best:.2f}x the default's time (best vs best)"
                      for c in configs
                      if c["order"] == order and c["method"] == "rkmk4" and not c["default"]]
        lines.append("- rk4_proj never calls the retraction, so its so3 and so3-exp rows run "
                     "the same code: their difference shows the measurement noise.")
    elif dim == 2:
        lines.append(
            "- rk4_proj needs matrices: in 2-D it always runs on the 2x2 matrix representation.")
    return lines + [COLD_CACHE_NOTE]


def headline(args, log, report):
    """Every configuration at --n, --dim interleaved, then the default rkmk4 in a run."""
    from ..timing import measure_interleaved

    n, dim = (500, 3) if args.quick else (args.n, args.dim)
    repeats = args.repeats or (3 if args.quick else 30)
    configs = _configurations(n, dim, args.dt)
    log(f"step: N = {n}, d = {dim}: {len(configs)} configurations x {repeats} repeats, "
        "interleaved")
    timings = measure_interleaved([(c["fn"], c["setup"]) for c in configs], repeats)
    for c, t in zip(configs, timings):
        c["timing"] = t
    _one_step_table(report, configs, n, dim, repeats)
    _rkmk4_table(args, log, report, configs, n, dim)
    report.text(*_headline_notes(configs, dim))
    return configs, n, dim


def dimension_ratios(args, log, report):
    """rkmk4 at one N for several d, interleaved: each d's cost against the previous d's."""
    from polymatch_ros.core import METHODS

    from ..scenes import representation_label, timing_scene
    from ..timing import fmt_ms, measure_interleaved

    n = 500 if args.quick else args.n
    dims = [2, 3, 4] if args.quick else args.ratio_dims
    repeats = args.repeats or (3 if args.quick else 15)
    scenes = [timing_scene(n, d, args.grid_order) for d in dims]
    log(f"step: dimension ratios at N = {n}: d = {dims}, {repeats} interleaved repeats")
    steppers = [_stepper(METHODS["rkmk4"], sc, args.dt) for sc in scenes]
    timings = measure_interleaved(steppers, repeats)
    rows = []
    for k, (d, sc, t) in enumerate(zip(dims, scenes, timings)):
        row = [d, representation_label(sc.model.rotations), fmt_ms(t.best), fmt_ms(t.median)]
        if k == 0:
            row += ["-", "-", "-"]
        else:
            prev_d, prev_t = dims[k - 1], timings[k - 1]
            row += [f"{t.best / prev_t.best:.2f}", f"{t.median / prev_t.median:.2f}",
                    f"{(d / prev_d) ** 3:.1f}"]
        rows.append(row)
    report.table(["d", "representation", "best ms", "median ms", "best / previous d",
                  "median / previous d", "(d / previous d)^3"], rows,
                 caption=f"rkmk4, one step at N = {n:,}, "
                         f"{ORDER_WORDS[args.grid_order]}-order model, "
                         f"dimensions interleaved ({repeats} repeats each)")
    report.text("- A step costs O(N d^3): the ratio to the previous dimension should stay near "
                "or below (d / previous d)^3; d = 3 (closed-form SoA) to d = 4 (matrices, "
                "so(4) = so(3) + so(3) as (6, N) rows, Cayley through quaternion pairs) is the "
                "change of representation.")
    return dict(zip(dims, timings))


# -- over N and d ---------------------------------------------------------------------------------


def _grid_notes(max_step_seconds, skipped):
    """Which cells were skipped and why, and what a step costs in each dimension."""
    from ..timing import fmt_time

    notes = [f"Cells predicted (linear in N from the previous N) to take longer than "
             f"{max_step_seconds:g} s per step are skipped (`--max-step-seconds`)."]
    if skipped:
        notes.append("Skipped: " + ", ".join(f"N = {n:,}, d = {d} (~{fmt_time(p)}/step)"
                                             for n, d, p in skipped) + ".")
    notes.append(
        "The cost is O(N d^3) per evaluation: d = 2 uses angles (SO(2) is abelian), d = 3 the "
        "structure-of-arrays Cayley map, d >= 4 N x d x d matrices with the Cayley map in "
        "closed form (d = 4) or by batched matrix products (d >= 5), no per-matrix solves.")
    return notes


def grid(args, log, report):
    """rkmk4, one configuration at a time, over N x d; cells predicted too slow are skipped."""
    from polymatch_ros.core import METHODS

    from ..scenes import representation_label, timing_scene
    from ..timing import fmt_ms, fmt_time, measure

    sizes = [10, 100, 1000] if args.quick else sorted(args.sizes)
    dims = [2, 3, 4] if args.quick else args.dims
    max_repeats = args.repeats or (3 if args.quick else 15)
    cell_budget = 0.5 if args.quick else 2.0
    results, skipped, rows = {}, [], []
    for dim in dims:
        row = [None] * len(sizes)
        prev = label = None
        for j, n in enumerate(sizes):
            predicted = prev[1] * n / prev[0] if prev else None
            if predicted is not None and predicted > args.max_step_seconds:
                row[j] = f"skipped (~{fmt_time(predicted)}/step predicted)"
                skipped.append((n, dim, predicted))
                continue
            scene = timing_scene(n, dim, args.grid_order)
            label = representation_label(scene.model.rotations)
            fn, setup = _stepper(METHODS["rkmk4"], scene, args.dt)
            repeats = (max_repeats if predicted is None
                       else max(3, min(max_repeats, int(cell_budget / predicted))))
            log(f"step grid: N = {n}, d = {dim}, {repeats} repeats")
            t = results[(n, dim)] = measure(fn, repeats, setup)
            row[j] = f"{fmt_ms(t.best)} / {fmt_ms(t.median)}"
            prev = (n, t.median)
        rows.append([f"{dim}: {label}"] + row)
    report.table(["d: representation"] + [f"N = {n:,}" for n in sizes], rows,
                 caption=f"rkmk4, one step, {ORDER_WORDS[args.grid_order]}-order model: "
                 "best / median ms (up to %d repeats, fewer for slow cells)" % max_repeats)
    report.text(*_grid_notes(args.max_step_seconds, skipped))
    return results, sizes, dims


# -- figures ------------------------------------------------------------------------------------


def _draw_methods(configs, n, dim, plt):
    """Bars: best ms per method, one bar per representation, one panel per model order."""
    import numpy as np

    fig, axes = plt.subplots(1, 2, figsize=(11, 4), sharey=True)
    methods = list(dict.fromkeys(c["method"] for c in configs))
    reps = list(dict.fromkeys(c["rep"] for c in configs))
    width = 0.8 / len(reps)
    for ax, order in zip(axes, (1, 2)):
        for k, rep in enumerate(reps):
            cs = [next(c for c in configs
                       if c["order"] == order and c["rep"] == rep and c["method"] == m)
                  for m in methods]
            x = np.arange(len(methods)) + (k - (len(reps) - 1) / 2) * width
            ax.bar(x, [c["timing"].best * 1e3 for c in cs], width, label=rep)
            ax.plot(x, [c["timing"].median * 1e3 for c in cs], "k_", ms=10)
        if n == 10_000 and dim == 3:
            ax.axhline(TARGET_SECONDS * 1e3, color="r", ls="--", lw=1,
                       label="target 4 ms (rkmk4)")
        ax.set_xticks(range(len(methods)), methods)
        ax.set_yscale("log")
        ax.set_title(f"{ORDER_WORDS[order]}-order model, N = {n:,}, d = {dim}")
    axes[0].set_ylabel("ms per step (bar: best, tick: median)")
    axes[1].legend(fontsize=8)
    return fig


def _draw_scaling(results, sizes, dims, plt):
    """log-log best ms per rkmk4 step over N, one line per d, against slope 1."""
    fig, ax = plt.subplots(figsize=(6, 4.5))
    for d in dims:
        ns = [n_ for n_ in sizes if (n_, d) in results]
        if ns:
            ax.loglog(ns, [results[(n_, d)].best * 1e3 for n_ in ns], "o-", label=f"d = {d}")
    if results:
        (n0, _d0), t0 = min(results.items())
        ax.loglog(sizes, [t0.best * 1e3 * s_ / n0 for s_ in sizes], "k:", lw=1,
                  label="slope 1 (O(N))")
    ax.axhline(TARGET_SECONDS * 1e3, color="r", ls="--", lw=1, label="4 ms")
    ax.set_xlabel("N (agents)")
    ax.set_ylabel("ms per rkmk4 step (best)")
    ax.legend(fontsize=8)
    ax.grid(True, which="both", alpha=0.3)
    return fig


def run(args, log):
    from functools import partial

    from ..report import Report

    report = Report(NAME, "One integrator step (`python -m benchmarks step`)")
    configs, n, dim = headline(args, log, report)
    dimension_ratios(args, log, report)
    results, sizes, dims = grid(args, log, report)
    report.figure("methods", partial(_draw_methods, configs, n, dim),
                  "one step per method and representation")
    report.figure("scaling", partial(_draw_scaling, results, sizes, dims),
                  "rkmk4 step time over N and d")
    return report
