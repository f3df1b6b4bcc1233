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
ORDER = 20

TARGET_SPEEDUP = 1000.0


def add_arguments(p):
    from .options import at_least, int_list
    p.add_argument("--sizes", type=int_list(2), default=[1000, 10_000, 100_000],
                   help="N values (default 1000,10000,100000)")
    p.add_argument("--dim", type=at_least(2), default=3, help="dimension (default 3)")
    p.add_argument("--sample", type=at_least(1), default=200,
                   help="agents the naive sum is timed on (default 200)")
    p.add_argument("--full-naive-max", type=at_least(0), default=2000,
                   help="also run the naive sum over ALL agents when N <= this (default 2000)")


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


def run(args, log):
    import numpy as np

    from ..core import System, with_representation
    from .report import Report
    from .scenes import representation_label, timing_scene
    from .timing import fmt_ms, fmt_time, measure

    report = Report(NAME, "Mean field vs naive double sum (`polymatch bench meanfield`)")
    dim = args.dim
    repeats = args.repeats or (3 if args.quick else 30)
    naive_repeats = 3
    sample_size = 20 if args.quick else args.sample
    rng = np.random.default_rng(0)
    rows, results = [], []
    for n in _sizes(args):
        base = timing_scene(n, dim, order=1)
        model = base.model
        scale = model.kappa / (2.0 * model.gamma * n)
        mats = model.rotations.to_matrices(base.initial.groups[0].rot)
        reps = ([base] if model.rotations.name == "matrix"
                else [base, with_representation(base, "matrix")])
        mf = []
        for scene in reps:
            system = System(scene.model)
            groups = scene.initial.groups

            def mean_field(_, system=system, groups=groups):
                c = system.couple(groups, first_stage=False)
                return system.rotation_rate(0, groups[0].rot, c)

            log(f"meanfield: N = {n}, {representation_label(scene.model.rotations)}, "
                f"{repeats} repeats")
            t = measure(mean_field, repeats)
            rate = scene.model.rotations.algebra_to_skew(mean_field(None))
            mf.append((representation_label(scene.model.rotations), t, rate))

        k = min(sample_size, n)
        idx = np.sort(rng.choice(n, size=k, replace=False))
        log(f"meanfield: N = {n}, naive sum over {k} sampled agents, {naive_repeats} passes")
        t_sample = measure(lambda _, mats=mats, idx=idx, scale=scale:
                           naive_rates(mats, idx, scale), naive_repeats)
        naive = naive_rates(mats, idx, scale)
        estimate = t_sample.scaled(n / k)
        full = None
        if n <= args.full_naive_max:
            log(f"meanfield: N = {n}, naive sum over all agents")
            everyone = np.arange(n)
            full = measure(lambda _, mats=mats, rows=everyone, scale=scale:
                           naive_rates(mats, rows, scale), naive_repeats, warmup=0)
        magnitude = float(np.abs(mf[0][2]).max())
        for label, t, rate in mf:
            diff = float(np.abs(rate[idx] - naive).max())
            rows.append([f"{n:,}", label, fmt_ms(t.best), fmt_ms(t.median),
                         f"{t_sample.best / k * 1e6:.1f} ({k} agents)",
                         f"{fmt_time(estimate.best)} (x {n:,}/{k})",
                         fmt_time(full.best) if full is not None else "not run",
                         f"{estimate.best / t.best:,.0f}x", f"{diff:.1e}"])
            results.append({"n": n, "rep": label, "mf": t, "naive": estimate, "full": full,
                            "diff": diff, "magnitude": magnitude})

    report.table(["N", "representation", "mean field best ms", "median ms",
                  "naive µs/agent (sample)", "naive total, scaled", "naive total, measured",
                  "speed-up (best/best)", "max abs diff"], rows,
                 caption=f"d = {dim}: System.couple + System.rotation_rate (all agents) vs "
                         f"sum_k (O_k O_i^T - O_i O_k^T) per agent")
    lines = [f"- The naive double sum is timed on a random sample of agents "
             f"({naive_repeats} passes, best) and scaled by N / sample; it was run over all N "
             f"agents only where \"naive total, measured\" has a figure "
             f"(N <= {args.full_naive_max:,}); speed-ups use the scaled total.",
             f"- Mean field: {repeats} repeats. \"max abs diff\" compares the sampled agents' "
             f"naive rates with the mean-field rates W_i (entries of magnitude up to "
             f"{max(r['magnitude'] for r in results):.2g})."]
    at = [r for r in results if r["n"] == 10_000 and dim == 3]
    for r in at:
        ratio = r["naive"].best / r["mf"].best
        met = "met" if ratio >= TARGET_SPEEDUP else "NOT met"
        lines.append(f"- N = 10,000, d = 3, {r['rep']}: mean field {ratio:,.0f}x faster than "
                     f"the naive sum (target >= {TARGET_SPEEDUP:,.0f}x: {met}; "
                     f"medians: {r['naive'].median / r['mf'].median:,.0f}x)")
    for r in results:
        if r["full"] is not None:
            lines.append(f"- Scaling check at N = {r['n']:,}: extrapolated naive total "
                         f"{fmt_time(r['naive'].best)}, "
                         f"measured over all agents {fmt_time(r['full'].best)} "
                         f"(ratio {r['full'].best / r['naive'].best:.2f}).")
            break
    report.text(*lines)

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

    report.figure("scaling", draw, "mean field vs naive double sum")
    return report
