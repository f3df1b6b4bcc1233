"""Tables, figure and findings of ``python -m benchmarks basins``
(``benchmarks/core_families/basins.py``)."""

import numpy as np

from ..report import Report

OUTCOME_SHORT = {"twisted": "twisted", "other equilibrium": "other eq.", "antipodal": "antipodal",
                 "too slow": "too slow"}


def _frac(result, outcome="matched"):
    return f"{int(np.sum(result.outcome == outcome))}/{len(result.outcome)}"


def _rest(result):
    """How the ensembles that did not match ended (only the kinds that occur)."""
    parts = [f"{OUTCOME_SHORT[o]} {int(np.sum(result.outcome == o))}" for o in OUTCOME_SHORT
             if np.any(result.outcome == o)]
    return ", ".join(parts) or "-"


def twist_summary(result, d):
    """Twisted ends: winding numbers (d = 2) or total turns with the loop class (d >= 3)."""
    twisted = result.outcome == "twisted"
    if result.ring is None or not twisted.any():
        return "-"
    if d == 2:
        q, c = np.unique(result.ring.winding[twisted], return_counts=True)
        return " ".join(f"{int(v):+d}:{n}" for v, n in zip(q, c))
    turns = np.rint(result.ring.turn[twisted]).astype(int)
    classes = result.ring.loop_class[twisted]
    out = []
    for t in np.unique(turns):
        sel = turns == t
        odd = int(np.sum(classes[sel] < 0))
        out.append(f"turn {t}: {int(sel.sum())} ({odd} non-contractible)")
    return "; ".join(out)


def ring_table(ring, dims):
    from .basins import stable_twists
    header = ["N", "k", "k/N", "stable q (d = 2)"]
    for d in dims:
        header += [f"d = {d} matched", f"d = {d} twisted ends"]
    header.append("not matched, by kind (all d)")
    rows = []
    for n, k in sorted({(n, k) for _, n, k in ring}):
        row = [n, k, f"{k / n:.3f}", stable_twists(n, k)]
        rest = []
        for d in dims:
            r = ring[d, n, k]
            row += [_frac(r), twist_summary(r, d)]
            if _rest(r) != "-":
                rest.append(f"d={d}: {_rest(r)}")
        rows.append(row + ["; ".join(rest) or "-"])
    return header, rows


def random_table(rand, dims):
    header = ["p", "mean degree"] + [f"d = {d} matched" for d in dims] + ["not matched, by kind"]
    rows = []
    for p in sorted({p for _, p in rand}):
        degree = np.mean([rand[d, p][1] for d in dims])
        rest = [f"d={d}: {_rest(rand[d, p][0])}" for d in dims if _rest(rand[d, p][0]) != "-"]
        rows.append([p, f"{degree:.1f}"] + [_frac(rand[d, p][0]) for d in dims]
                    + ["; ".join(rest) or "-"])
    return header, rows


def winding_table(ring):
    """The distribution of q (d = 2) per ring cell that has twisted ends."""
    from .basins import stable_twists
    rows = []
    for (d, n, k), r in sorted(ring.items()):
        if d != 2 or r.ring is None or not np.any(r.outcome == "twisted"):
            continue
        settled = (r.outcome == "matched") | (r.outcome == "twisted")
        q = r.ring.winding[settled]
        values, counts = np.unique(np.abs(q), return_counts=True)
        dist = " ".join(f"{int(v)}:{c}" for v, c in zip(values, counts))
        rows.append([n, k, f"{k / n:.3f}", int(settled.sum()), dist, f"{q.mean():+.2f}",
                     f"{q.var():.2f}", int(np.abs(q).max()), stable_twists(n, k)])
    return ["N", "k", "k/N", "settled", "|q|: count", "mean q", "var q", "max |q|",
            "stable q"], rows


def twist_table(twist, n):
    """One row per (d, k, q, eps) of the perturbed twisted states (``n`` agents)."""
    header = ["d", "k", "q", "eps", "ensembles", "matched", "twisted ends", "other"]
    rows = []
    for (d, k, q, eps), r in sorted(twist.items()):
        other = [f"{OUTCOME_SHORT[o]} {int(np.sum(r.outcome == o))}" for o in OUTCOME_SHORT
                 if o != "twisted" and np.any(r.outcome == o)]
        rows.append([d, k, q, eps, len(r.outcome), _frac(r), twist_summary(r, d),
                     ", ".join(other) or "-"])
    return header, rows


def findings(ring, twist):
    """Statements computed from the runs (no number here is typed in)."""
    from .basins import WSG_CRITICAL, stable_twists
    lines = []
    for d in sorted({d for d, _, _ in ring}):
        cells = {(n, k): r for (dd, n, k), r in ring.items() if dd == d}
        full = [k / n for (n, k), r in cells.items() if np.all(r.outcome == "matched")]
        short = [k / n for (n, k), r in cells.items() if not np.all(r.outcome == "matched")]
        edge = max(short) if short else 0.0
        above = all(np.all(r.outcome == "matched") for (n, k), r in cells.items()
                    if k / n > WSG_CRITICAL)
        lines.append(f"- d = {d}: the largest k/N with an ensemble not matched is {edge:.3f}; "
                     f"every ensemble matched in every cell with k/N > {WSG_CRITICAL} "
                     f"({'yes' if above else 'no'}; {len(full)} of {len(cells)} cells matched "
                     "in full).")
    within = [(abs(q) <= stable_twists(n, k)) for (d, n, k), r in ring.items()
              if d == 2 and r.ring is not None
              for q in r.ring.winding[r.outcome == "twisted"]]
    if within:
        lines.append(f"- d = 2: {sum(within)} of {len(within)} twisted ends have |q| within "
                     "the linearly stable twists of their ring (`stable q`).")
    for d in sorted({d for d, _, _, _ in twist}):
        for q in sorted({q for _, _, q, _ in twist}):
            rs = [r for (dd, _, qq, _), r in twist.items() if dd == d and qq == q]
            b = sum(len(r.outcome) for r in rs)
            m = sum(int(np.sum(r.outcome == "matched")) for r in rs)
            if d == 2:
                wound = np.concatenate([r.ring.winding[r.outcome == "twisted"] for r in rs])
                kept = int(np.sum(np.abs(wound) == q))
                lines.append(f"- perturbed {q}-twists, d = 2: {m}/{b} matched; {kept}/{b} "
                             f"ended twisted with |q| = {q}, {len(wound) - kept} with another q.")
                continue
            odd = sum(int(np.sum((r.outcome == "twisted") & (r.ring.loop_class < 0))) for r in rs)
            same = sum(int(np.sum((r.outcome == "twisted") & (np.rint(r.ring.turn) == q)))
                       for r in rs)
            lines.append(f"- perturbed {q}-twists, d = {d}: {m}/{b} matched; {odd}/{b} ended "
                         f"twisted with a non-contractible loop; {same}/{b} kept a total turn "
                         f"of {q}.")
    return lines


def figure(ring, rand, dims):
    def draw(plt):
        fig, axes = plt.subplots(1, 3, figsize=(13.5, 3.8))
        markers = {16: "o", 32: "s", 64: "^", 8: "o"}
        colours = {2: "tab:blue", 3: "tab:orange", 4: "tab:green"}
        for (d, n) in sorted({(d, n) for d, n, _ in ring}):
            ks = sorted(k for dd, nn, k in ring if (dd, nn) == (d, n))
            frac = [np.mean(ring[d, n, k].outcome == "matched") for k in ks]
            axes[0].plot([k / n for k in ks], frac, marker=markers.get(n, "o"), ms=4, lw=1,
                         color=colours.get(d), label=f"d = {d}, N = {n}")
        axes[0].axvline(0.34, color="grey", ls="--", lw=0.8)
        axes[0].set(xlabel="k / N (ring, k neighbours a side)", ylabel="fraction matched",
                    title="rings: Haar-uniform rotations")
        axes[0].legend(fontsize=6, ncol=3)
        for d in dims:
            ps = sorted(p for dd, p in rand if dd == d)
            axes[1].plot(ps, [np.mean(rand[d, p][0].outcome == "matched") for p in ps], "o-",
                         color=colours.get(d), label=f"d = {d}")
        axes[1].set(xlabel="p (connected G(32, p))", ylabel="fraction matched",
                    title="random graphs", ylim=(-0.05, 1.05))
        axes[1].legend(fontsize=7)
        _winding_panel(axes[2], ring)
        fig.tight_layout()
        return fig
    return draw


def _winding_panel(ax, ring):
    n = max(nn for d, nn, _ in ring if d == 2) if any(d == 2 for d, _, _ in ring) else None
    if n is None:
        return
    for k in sorted(k for d, nn, k in ring if d == 2 and nn == n)[:4]:
        r = ring[2, n, k]
        q = r.ring.winding[(r.outcome == "matched") | (r.outcome == "twisted")]
        if len(q) == 0 or np.all(q == 0):
            continue
        values = np.arange(q.min(), q.max() + 1)
        ax.plot(values, [np.mean(q == v) for v in values], "o-", ms=3, label=f"k = {k}")
    ax.set(xlabel="winding number q (d = 2)", ylabel="fraction of ensembles",
           title=f"d = 2 ring, N = {n}: final q")
    ax.legend(fontsize=7)


def report(name, args, ring, rand, twist):
    dims = list(args.dims)[:2] if args.quick else list(args.dims)      # as ``basins._dims``
    rep = Report(name, "Basins of consensus on sparse graphs (`python -m benchmarks basins`)")
    rep.text("First-order model (A-2) with degree-normalised weights, centroids together, "
             "Haar-uniform rotations, seeds 0 .. B-1 per cell; rkmk4 dt 0.5; an ensemble stops "
             "when it has matched (diameter < 1e-6) or is still (max |W_i| < 1e-6 times the "
             "coupling rate) away from consensus.  See the module doc of "
             "benchmarks/core_families/basins.py.")
    rep.figure("fractions", figure(ring, rand, dims),
               "fraction matched against k/N on rings and p on random graphs; final q in 2-D")
    rep.table(*ring_table(ring, dims), caption="Rings: matched / ensembles and the twisted ends")
    rep.table(*random_table(rand, dims), caption="Connected random graphs G(32, p)")
    rep.table(*winding_table(ring), caption="d = 2: final winding numbers (matched = q 0)")
    n = len(next(iter(twist.values())).final_rot[0]) if twist else 0
    rep.table(*twist_table(twist, n), caption=f"Perturbed q-twisted rings of {n} agents")
    rep.text("Findings (computed from the runs above):", *findings(ring, twist))
    return rep
