"""A batched sweep against a loop of scipy DOP853 solves of the same ensembles.

B random ensembles of the Fig. 1 scene (seeds 0 .. B-1 of ``config/congruent_triangles``)
are integrated to the scene's tolerance (each until its matching diameter is below it at
a sample) by ``core.sweep.run_batch``, by default with rkmk8 (DOP853's 8th-order tableau
as a fixed-step Munthe-Kaas method, ``core.sweep.chart_rk``) at the scene's sample interval;
``--integrator rkmk4 --dt 0.05`` is the scene's own integrator.  The same ensembles
are then solved one at a time by scipy's DOP853 on the flattened system of
``benchmarks/core_families/paper_rhs.py`` (``benchmarks/core_families/solve.py``), each to the
time at which the batch saw it match.

Error: the largest vertex error max_{i,a} |x^i_a - x^i_a,ref| over the ensembles and every
sample up to that time, against a reference of the same batch (same method) at dt/16.
scipy's tolerance is the loosest of 1e-4, 3e-5, 1e-5, ... 1e-12 whose error on a calibration
subset is at most the batch's (the same max error); the timed loop runs at that tolerance,
and again one notch tighter while its own max error (reported) exceeds the batch's.
If a loop of B scipy solves is too long (--scipy-ensembles), a subset is timed and the
ratio is per ensemble (stated in the output).  The batch is timed --repeats times before
the scipy loop and once after every 200 of its solves; its figure is the median of those
runs, so both sides see the same machine load.
"""

NAME = "sweep"
HELP = "batched sweep of 1,000 Fig. 1 ensembles vs a loop of scipy DOP853 solves"

TARGET_SPEEDUP = 50.0
TOLERANCES = tuple(f * 10.0 ** -e for e in range(4, 13) for f in (3.0, 1.0))[1:]
CALIBRATION = 20
#: scipy solves between two timed batch runs
CHUNK = 200


def add_arguments(p):
    from ..options import at_least
    p.add_argument("--ensembles", type=at_least(1), default=1000,
                   help="ensembles (default 1000)")
    p.add_argument("--scipy-ensembles", type=at_least(1), default=1000,
                   help="how many of them scipy solves in the timed loop (default all 1000)")
    p.add_argument("--scene", default="congruent_triangles", help="template scene")
    p.add_argument("--integrator", default="rkmk8",
                   help="the batch's fixed-step integrator (default rkmk8)")
    p.add_argument("--dt", type=at_least(1e-6, float),
                   help="the batch's step (default: rkmk8 the scene's sample interval, "
                        "other integrators the scene's dt)")


class SampledVertices:
    """Vertices x^i_a of the live ensembles at every sample (``run_batch``'s observe hook)."""

    def __init__(self, scene):
        self.grp, self.ref = scene.model.rotations, scene.model.groups[0].reference
        self.n, self.at = scene.model.n_agents, {}

    def __call__(self, state, live):
        from polymatch_ros.core.metrics import vertices
        gs = state.groups[0]
        verts = vertices(gs.x, self.grp.to_matrices(gs.rot), self.ref)
        self.at[time_key(state.t)] = (live.copy(), verts.reshape((len(live), self.n) +
                                                                   verts.shape[1:]))

    def error(self, reference) -> float:
        """max over samples, ensembles, agents and vertices of |x - x_ref|."""
        import numpy as np
        worst = 0.0
        for t, (live, verts) in self.at.items():
            ref_live, ref_verts = reference.at[t]
            rows = np.searchsorted(ref_live, live)
            diff = verts - ref_verts[rows]
            worst = max(worst, float(np.sqrt((diff ** 2).sum(axis=-1)).max()))
        return worst


def time_key(t):
    """Sample times of runs at different steps, as one dictionary key."""
    return round(float(t), 6)


def reference_run(scenes, final_t, sample_times, method, dt):
    """The same ensembles at dt, never leaving the batch, to the last time any matched."""
    from dataclasses import replace

    from polymatch_ros.core.sweep.run import run_batch
    ref = SampledVertices(scenes[0])
    t_end = float(final_t.max())
    run_batch([replace(s, t_end=t_end, tolerance=0.0, samples=sample_times) for s in scenes],
              method, dt, observe=ref)
    return ref


def scipy_loop(scenes, final_t, sample_times, tol, log=None, between=None):
    """scipy DOP853 of each scene to its final_t: (SampledVertices, wall time).

    ``between()`` is called after every CHUNK solves (outside the timed solves).
    """
    import time
    from dataclasses import replace

    import numpy as np

    from polymatch_ros.core.metrics import vertices

    from .paper_rhs import FlatSystem
    from .solve import Solver, solve
    solver = Solver("DOP853", "scipy", tol)
    flat = FlatSystem.for_scene(scenes[0])
    out = SampledVertices(scenes[0])
    solutions, wall = [], 0.0
    for b, (scene, t) in enumerate(zip(scenes, final_t)):
        times = sample_times[sample_times <= t + 1e-9]
        t0 = time.perf_counter()
        solutions.append(solve(replace(scene, t_end=float(t)), solver, times, flat))
        wall += time.perf_counter() - t0
        if (b + 1) % CHUNK == 0 and log is not None:
            log(f"scipy DOP853 tol {tol:g}: {b + 1}/{len(scenes)} solves")
        if (b + 1) % CHUNK == 0 and between is not None:
            between()
    for b, (scene, sol) in enumerate(zip(scenes, solutions)):
        verts = vertices(sol.centroids - scene.origin, sol.mats, out.ref)
        for k, t in enumerate(sol.times):
            out.at[time_key(t)] = out.at.get(time_key(t), (np.zeros(0, int), []))
            live, parts = out.at[time_key(t)]
            out.at[time_key(t)] = (np.append(live, b), parts + [verts[k]])
    out.at = {t: (live, np.array(parts)) for t, (live, parts) in out.at.items()}
    return out, wall


class BatchTimer:
    """Timed batch runs: some before the scipy loop, one after each CHUNK of its solves, so
    both sides are measured under the same machine load; the figure is their median."""

    def __init__(self, scenes, integrator, dt):
        self.scenes, self.integrator, self.dt = scenes, integrator, dt
        self.walls, self.result, self.before = [], None, 0

    def __call__(self):
        import time

        from polymatch_ros.core.sweep.run import run_batch
        t0 = time.perf_counter()
        self.result = run_batch(self.scenes, self.integrator, self.dt)
        self.walls.append(time.perf_counter() - t0)

    @property
    def wall(self) -> float:
        import numpy as np
        return float(np.median(self.walls))


def scipy_at_error(scenes, batch, reference, err, n_scipy, calibration, log, between):
    """(solved, wall, tolerance) of the timed scipy loop at the batch's max error (module doc)."""
    start = len(TOLERANCES) - 1
    for k, tol in enumerate(TOLERANCES):
        trial, _ = scipy_loop(scenes[:calibration], batch.final_t[:calibration], batch.times,
                              tol)
        if trial.error(reference) <= err:
            start = k
            break
    for chosen in TOLERANCES[start:]:      # tighten until the timed set is within err too
        log(f"scipy DOP853 at tol {chosen:g}: timing {n_scipy} solves")
        solved, wall = scipy_loop(scenes[:n_scipy], batch.final_t[:n_scipy], batch.times,
                                  chosen, log, between)
        if solved.error(reference) <= err:
            break
    return solved, wall, chosen


def run(args, log):
    from polymatch_ros.core.sweep.run import run_batch
    from polymatch_ros.core.sweep.scenes import Cell, cell_scenes, template
    b = 20 if args.quick else args.ensembles
    n_scipy = min(b, 5 if args.quick else args.scipy_ensembles)
    log(f"building {b} ensembles of {args.scene}")
    scenes = cell_scenes(template(args.scene), Cell(), b, seed=0)
    timer = BatchTimer(scenes, args.integrator, args.dt)
    timer.before = args.repeats or 3
    for _ in range(timer.before):
        timer()
    batch = timer.result
    log(f"batch: {b} ensembles in {timer.wall:.3f} s (median of {len(timer.walls)})")
    observed = SampledVertices(scenes[0])
    run_batch(scenes, args.integrator, args.dt, observe=observed)
    reference = reference_run(scenes, batch.final_t, batch.times, args.integrator,
                              batch.dt / 16)
    err = observed.error(reference)
    solved, scipy_wall, chosen = scipy_at_error(scenes, batch, reference, err, n_scipy,
                                                min(3 if args.quick else CALIBRATION, b), log,
                                                timer)
    return _report(scenes, batch, timer, err, (solved.error(reference), scipy_wall, chosen,
                                               n_scipy))


def _report(scenes, batch, timer, err, scipy):
    import numpy as np

    from ..report import Report
    scipy_err, scipy_wall, chosen, n_scipy = scipy
    b, wall = len(scenes), timer.wall
    per_batch, per_scipy = wall / b, scipy_wall / n_scipy
    report = Report(NAME, f"sweep: {b} ensembles of {scenes[0].name} batched vs scipy DOP853")
    report.table(["solver", "ensembles timed", "wall s", "s per ensemble", "max vertex error",
                  "setting"],
                 [[f"batch ({batch.method})", b, f"{wall:.3f}", f"{per_batch:.2e}",
                   f"{err:.2e}", f"dt = {batch.dt:g}, {batch.steps} steps"],
                  ["scipy DOP853 loop", n_scipy, f"{scipy_wall:.3f}", f"{per_scipy:.2e}",
                   f"{scipy_err:.2e}", f"rtol = atol = {chosen:g}"]])
    matched = int(np.sum(batch.outcome == "matched"))
    subset = "" if n_scipy == b else (f" scipy timed on {n_scipy} of the {b} ensembles; the "
                                      "ratio compares time per ensemble.")
    report.text(f"{matched}/{b} ensembles matched (tolerance {scenes[0].tolerance:g}); each "
                f"integrated to the sample where it matched.{subset} Batch wall: the median "
                f"of {len(timer.walls)} runs, {timer.before} before the scipy loop and "
                f"{len(timer.walls) - timer.before} during it (best {min(timer.walls):.3f} s, "
                f"worst {max(timer.walls):.3f} s).",
                f"Speed-up (scipy loop / batch, per ensemble, same max error): "
                f"**{per_scipy / per_batch:.0f}x** (goal >= {TARGET_SPEEDUP:g}x). Errors: max "
                "over samples, ensembles and vertices against the batch at dt/16.")
    return report
