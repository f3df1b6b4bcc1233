"""The mean field against the naive O(N^2) double sum of the rotation coupling.

The coupling of agent i in (A-1) and (A-2) is a sum over all agents,

    sum_k (O_k O_i^T - O_i O_k^T) = S O_i^T - O_i S^T,      S = sum_k O_k,

so the whole ensemble costs O(N d^3) with the mean field S instead of the
O(N^2 d^3) of the double sum.  The mean-field figure is ``System.couple``
(computes S) plus ``System.rotation_rate`` (W_i = kappa/(2 gamma N)
(S O_i^T - O_i S^T) for every agent) -- exactly what every integrator stage runs.

The naive sum is timed per agent i, vectorised over k with numpy (one BLAS
product O_k O_i^T for every k, then sum_k of the product minus its
transpose).  All N agents would take minutes at N = 10,000, so it runs for a
random sample of agents and the total is that time scaled by N / sample;
where N is small enough it is also run over all agents, which checks the
scaling.  The sampled agents' naive rates are compared with the mean-field
rates (max abs difference).
"""

NAME = "meanfield"
HELP = "mean-field coupling vs the naive O(N^2) double sum (N = 10,000, d = 3)"

TARGET_SPEEDUP = 1000.0


def add_arguments(p):
    from ..options import add_number, int_list
    p.add_argument("--sizes", type=int_list(2), default=[1000, 10_000, 100_000],
                   help="N values (default 1000,10000,100000)")
    add_number(p, "--dim", 2, 3, "dimension")
    add_number(p, "--sample", 1, 200, "agents the naive sum is timed on")
    add_number(p, "--full-naive-max", 0, 2000,
               "also run the naive sum over ALL agents when N <= this")


def naive_rates(mats, idx, scale):
    """kappa/(2 gamma N) sum_k (O_k O_i^T - O_i O_k^T) for the agents ``idx``, one at a time."""
    import numpy as np
    n, d, _ = mats.shape
    flat = mats.reshape(n * d, d)
    out = np.empty((len(idx), d, d))
    for j, i in enumerate(idx):
        p = (flat @ mats[i].T).reshape(n, d, d)            # O_k O_i^T for every k
        out[j] = (p - p.transpose(0, 2, 1)).sum(axis=0)     # sum_k (O_k O_i^T - O_i O_k^T)
    return scale * out


def _sizes(args):
    return [300] if args.quick else args.sizes


NAIVE_REPEATS = 3


def _mean_field_timings(base, repeats, log):
    """(representation, Timing, rates W_i as skew matrices) of the mean field in the scene's
    own representation and, if that is not d x d matrices, in matrices too."""
    from polymatch_ros.core import System, with_representation

    from ..scenes import representation_label
    from ..timing import measure

    n = base.model.n_agents
    reps = ([base] if base.model.rotations.name == "matrix"
            else [base, with_representation(base, "matrix")])
    out = []
    for scene in reps:
        system = System(scene.model)
        groups = scene.initial.groups

        def mean_field(_, system=system, groups=groups):
            c = system.couple(groups, first_stage=False)
            return system.rotation_rate(0, groups[0].rot, c)

        label = representation_label(scene.model.rotations)
        log(f"meanfield: N = {n}, {label}, {repeats} repeats")
        t = measure(mean_field, repeats)
        out.append((label, t, scene.model.rotations.algebra_to_skew(mean_field(None))))
    return out


def _naive_timings(base, idx, full_naive_max, log):
    """The naive sum on the sampled agents ``idx``: (Timing of the sample, their rates, the
    Timing scaled to all N, Timing over all agents or None when N > ``full_naive_max``)."""
    import numpy as np

    from ..timing import measure

    model = base.model
    n, k = model.n_agents, len(idx)
    scale = model.kappa / (2.0 * model.gamma * n)
    mats = model.rotations.to_matrices(base.initial.groups[0].rot)
    log(f"meanfield: N = {n}, naive sum over {k} sampled agents, {NAIVE_REPEATS} passes")
    t_sample = measure(lambda _: naive_rates(mats, idx, scale), NAIVE_REPEATS)
    naive = naive_rates(mats, idx, scale)
    full = None
    if n <= full_naive_max:
        log(f"meanfield: N = {n}, naive sum over all agents")
        everyone = np.arange(n)
        full = measure(lambda _: naive_rates(mats, everyone, scale), NAIVE_REPEATS, warmup=0)
    return t_sample, naive, t_sample.scaled(n / k), full


def _measure_size(n, dim, repeats, sample_size, full_naive_max, rng, log):
    """Table rows and result records of N = ``n``, one per representation of the mean field."""
    import numpy as np

    from ..scenes import timing_scene
    from ..timing import fmt_ms, fmt_time

    base = timing_scene(n, dim, order=1)
    mf = _mean_field_timings(base, repeats, log)
    k = min(sample_size, n)
    idx = np.sort(rng.choice(n, size=k, replace=False))
    t_sample, naive, estimate, full = _naive_timings(base, idx, full_naive_max, log)
    magnitude = float(np.abs(mf[0][2]).max())
    rows, results = [], []
    for label, t, rate in mf:
        diff = float(np.abs(rate[idx] - naive).max())
        rows.append([f"{n:,}", label, fmt_ms(t.best), fmt_ms(t.median),
                     f"{t_sample.best / k * 1e6:.1f} ({k} agents)",
                     f"{fmt_time(estimate.best)} (x {n:,}/{k})",
                     fmt_time(full.best) if full is not None else "not run",
                     f"{estimate.best / t.best:,.0f}x", f"{diff:.1e}"])
        results.append({"n": n, "rep": label, "mf": t, "naive": estimate, "full": full,
                        "diff": diff, "magnitude": magnitude})
    return rows, results


def _notes(results, dim, repeats, full_naive_max):
    from ..timing import fmt_time

    lines = [f"- The naive double sum is timed on a random sample of agents "
             f"({NAIVE_REPEATS} passes, best) and scaled by N / sample; it was run over all N "
             f"agents only where \"naive total, measured\" has a figure "
             f"(N <= {full_naive_max:,}); speed-ups use the scaled total.",
             f"- Mean field: {repeats} repeats. \"max abs diff\" compares the sampled agents' "
             f"naive rates with the mean-field rates W_i (entries of magnitude up to "
             f"{max(r['magnitude'] for r in results):.2g})."]
    for r in (r for r in results if r["n"] == 10_000 and dim == 3):
        ratio = r["naive"].best / r["mf"].best
        met = "met" if ratio >= TARGET_SPEEDUP else "NOT met"
        lines.append(f"- N = 10,000, d = 3, {r['rep']}: mean field {ratio:,.0f}x faster than "
                     f"the naive sum (target >= {TARGET_SPEEDUP:,.0f}x: {met}; "
                     f"medians: {r['naive'].median / r['mf'].median:,.0f}x)")
    checked = next((r for r in results if r["full"] is not None), None)
    if checked is not None:
        lines.append(f"- Scaling check at N = {checked['n']:,}: extrapolated naive total "
                     f"{fmt_time(checked['naive'].best)}, "
                     f"measured over all agents {fmt_time(checked['full'].best)} "
                     f"(ratio {checked['full'].best / checked['naive'].best:.2f}).")
    return lines


def _scaling_figure(results, dim):
    def draw(plt):
        fig, ax = plt.subplots(figsize=(6, 4.5))
        for rep in dict.fromkeys(r["rep"] for r in results):
            rs = [r for r in results if r["rep"] == rep]
            ax.loglog([r["n"] for r in rs], [r["mf"].best * 1e3 for r in rs],
                      "o-", label=f"mean field, {rep}")
        first = [r for r in results if r["rep"] == results[0]["rep"]]
        ax.loglog([r["n"] for r in first], [r["naive"].best * 1e3 for r in first], "s--",
                  label="naive double sum (sampled, scaled by N/sample)")
        meas = [r for r in first if r["full"] is not None]
        if meas:
            ax.loglog([r["n"] for r in meas], [r["full"].best * 1e3 for r in meas], "kx", ms=10,
                      label="naive, all agents measured")
        ax.set_xlabel("N (agents)")
        ax.set_ylabel("ms for all agents' coupling (best)")
        ax.set_title(f"rotation coupling, d = {dim}")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
        return fig
    return draw


def run(args, log):
    import numpy as np

    from ..report import Report

    report = Report(NAME, "Mean field vs naive double sum (`python -m benchmarks meanfield`)")
    dim = args.dim
    repeats = args.repeats or (3 if args.quick else 30)
    sample_size = 20 if args.quick else args.sample
    rng = np.random.default_rng(0)
    rows, results = [], []
    for n in _sizes(args):
        size_rows, size_results = _measure_size(n, dim, repeats, sample_size,
                                                args.full_naive_max, rng, log)
        rows += size_rows
        results += size_results
    report.table(["N", "representation", "mean field best ms", "median ms",
                  "naive µs/agent (sample)", "naive total, scaled", "naive total, measured",
                  "speed-up (best/best)", "max abs diff"], rows,
                 caption=f"d = {dim}: System.couple + System.rotation_rate (all agents) vs "
                         f"sum_k (O_k O_i^T - O_i O_k^T) per agent")
    report.text(*_notes(results, dim, repeats, args.full_naive_max))
    report.figure("scaling", _scaling_figure(results, dim), "mean field vs naive double sum")
    return report
