"""A batched sweep against a loop of scipy DOP853 solves of the same ensembles.

B random ensembles of the Fig. 1 scene (seeds 0 .. B-1 of ``config/congruent_triangles``)
are integrated to the scene's tolerance (each until its matching diameter is below it at
a sample) by ``core.sweep.run_batch``, by default with rkmk8 (DOP853's 8th-order tableau
as a fixed-step Munthe-Kaas method, ``core.chart_rk``) at the scene's sample interval;
``--integrator rkmk4 --dt 0.05`` is the scene's own integrator.  The same ensembles
are then solved one at a time by scipy's DOP853 on the flattened system of
``bench/flat.py`` (``bench/solve.py``), each to the time at which the batch saw it match.

Error: the largest vertex error max_{i,a} |x^i_a - x^i_a,ref| over the ensembles and every
sample up to that time, against a reference of the same batch (same method) at dt/16.
scipy's tolerance is the loosest of 1e-4, 3e-5, 1e-5, ... 1e-12 whose error on a calibration
subset is at most the batch's (the same max error); the timed loop runs at that tolerance,
and again one notch tighter while its own max error (reported) exceeds the batch's.
If a loop of B scipy solves is too long (--scipy-ensembles), a subset is timed and the
ratio is per ensemble (stated in the output).
"""

NAME = "sweep"
HELP = "batched sweep of 1,000 Fig. 1 ensembles vs a loop of scipy DOP853 solves"
ORDER = 60

TARGET_SPEEDUP = 50.0
TOLERANCES = tuple(f * 10.0 ** -e for e in range(4, 13) for f in (3.0, 1.0))[1:]
CALIBRATION = 20


def add_arguments(p):
    from .options import at_least
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
        from ..core.metrics import vertices
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

    from ..core.sweep import run_batch
    ref = SampledVertices(scenes[0])
    t_end = float(final_t.max())
    run_batch([replace(s, t_end=t_end, tolerance=0.0, samples=sample_times) for s in scenes],
              method, dt, observe=ref)
    return ref


def scipy_loop(scenes, final_t, sample_times, tol, log=None):
    """scipy DOP853 of each scene to its final_t: (SampledVertices, wall time)."""
    import time
    from dataclasses import replace

    import numpy as np

    from ..core.metrics import vertices
    from .flat import FlatSystem
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
        if log is not None and (b + 1) % 200 == 0:
            log(f"scipy DOP853 tol {tol:g}: {b + 1}/{len(scenes)} solves")
    for b, (scene, sol) in enumerate(zip(scenes, solutions)):
        verts = vertices(sol.centroids - scene.origin, sol.mats, out.ref)
        for k, t in enumerate(sol.times):
            out.at[time_key(t)] = out.at.get(time_key(t), (np.zeros(0, int), []))
            live, parts = out.at[time_key(t)]
            out.at[time_key(t)] = (np.append(live, b), parts + [verts[k]])
    out.at = {t: (live, np.array(parts)) for t, (live, parts) in out.at.items()}
    return out, wall


def run(args, log):
    import time

    import numpy as np

    from ..core.sweep import run_batch
    from ..core.sweep_scenes import Cell, cell_scenes, template
    from .report import Report
    b = 20 if args.quick else args.ensembles
    n_scipy = min(b, 5 if args.quick else args.scipy_ensembles)
    log(f"building {b} ensembles of {args.scene}")
    scenes = cell_scenes(template(args.scene), Cell(), b, seed=0)
    repeats = args.repeats or 3
    walls = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        batch = run_batch(scenes, args.integrator, args.dt)
        walls.append(time.perf_counter() - t0)
    wall = min(walls)
    log(f"batch: {b} ensembles in {wall:.3f} s (best of {repeats})")
    observed = SampledVertices(scenes[0])
    run_batch(scenes, args.integrator, args.dt, observe=observed)
    reference = reference_run(scenes, batch.final_t, batch.times, args.integrator,
                              batch.dt / 16)
    err = observed.error(reference)
    cal = min(3 if args.quick else CALIBRATION, b)
    start = len(TOLERANCES) - 1
    for k, tol in enumerate(TOLERANCES):
        trial, _ = scipy_loop(scenes[:cal], batch.final_t[:cal], batch.times, tol)
        if trial.error(reference) <= err:
            start = k
            break
    for chosen in TOLERANCES[start:]:      # tighten until the timed set is within err too
        log(f"scipy DOP853 at tol {chosen:g}: timing {n_scipy} solves")
        solved, scipy_wall = scipy_loop(scenes[:n_scipy], batch.final_t[:n_scipy],
                                        batch.times, chosen, log)
        scipy_err = solved.error(reference)
        if scipy_err <= err:
            break
    per_batch, per_scipy = wall / b, scipy_wall / n_scipy
    ratio = per_scipy / per_batch
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
                f"integrated to the sample where it matched.{subset}",
                f"Speed-up (scipy loop / batch, per ensemble, same max error): **{ratio:.0f}x** "
                f"(goal >= {TARGET_SPEEDUP:g}x). Errors: max over samples, ensembles and "
                "vertices against the batch at dt/16.")
    return report
