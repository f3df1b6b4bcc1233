"""The tables and figures of `polymatch bench precision` from its scored cells (``bench/solve.py``
``Solver``): every solver of a case, observed orders, the frontier, error vs cost."""


def _fmt_err(e):
    return f"{e:.2e}"


def case_table(cells, repeats):
    from .timing import fmt_ms
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

    from ..core import METHODS
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
    from .timing import fmt_ms

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
