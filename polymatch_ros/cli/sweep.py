"""`polymatch sweep`: many random ensembles of one scene, integrated in batches (core.sweep).

    polymatch sweep congruent_triangles --ensembles 500 --d0 0 2 --dimension 2,3 --agents 3,8 \\
        --order 1,2 --mass 0.5 --save sweep.npz --figure sweep.png
    polymatch sweep congruent_triangles --graph ring:1,ring:4,random:0.3 --agents 32 --settle

One batch per cell of the grid (d, N, order, kappa, gamma, m, graph); B ensembles per cell
(seeds seed .. seed + B - 1 of the scene's own draws, rotations redrawn at D0 uniform in
--d0; a random graph drawn per ensemble).  Prints a progress line per batch, a summary
table (how many matched, how the others ended), on rings the twists of the twisted ends,
and optionally an npz of per-ensemble outcomes and a figure.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from typing import Any

import numpy as np

from ..console import Progress, format_table, positive_float, writable_output
from ..core.sweep import BatchResult

#: one cell's result: (its label, the seeds of its ensembles, the batch's outcomes)
CellResult = tuple[dict[str, Any], np.ndarray, BatchResult]

HEADER: list[str] = ["d", "N", "order", "kappa", "gamma", "m", "graph", "ensembles", "D0 range",
                     "matched", "antipodal", "twisted", "other eq.", "too slow", "median t_match",
                     "wall s"]


def _list(kind: Callable[[str], float], minimum: float,
          what: str) -> Callable[[str], tuple[float, ...]]:
    def parse(text: str) -> tuple[float, ...]:
        out = []
        for part in text.split(","):
            try:
                value = kind(part)
            except ValueError:
                raise argparse.ArgumentTypeError(f"expected {what}, got {part!r}") from None
            if not np.isfinite(value) or value < minimum:
                raise argparse.ArgumentTypeError(f"{what} must be >= {minimum}, got {part}")
            out.append(value)
        return tuple(out)
    return parse


def _int_in(lo: int, hi: int) -> Callable[[str], int]:
    """An argparse type: an integer in [lo, hi]."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f"must be in {lo}..{hi}, got {value}")
        return value
    return parse


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """The ``sweep`` subcommand (its parser returned)."""
    p = sub.add_parser("sweep", help="many random ensembles in batches: which initial states "
                       "match", description=__doc__.split("\n\n")[0])
    p.add_argument("scene", nargs="?", default="congruent_triangles",
                   help="template scene with one group (default: congruent_triangles, Fig. 1)")
    p.add_argument("--ensembles", "-B", type=_int_in(1, 100_000), default=100,
                   help="ensembles per cell")
    p.add_argument("--seed", type=_int_in(0, 2**62), default=0, help="first seed (default 0)")
    p.add_argument("--d0", type=_list(float, 0.0, "a rotation diameter"), metavar="LO,HI",
                   help="redraw rotations at D0 = max |O_i - O_j|_F uniform in [LO, HI]")
    p.add_argument("--dimension", type=_list(int, 2, "a dimension"), default=(None,),
                   metavar="D,D", help="comma-separated dimensions d >= 2 (default: the scene's)")
    p.add_argument("--agents", type=_list(int, 2, "an agent count"), default=(None,),
                   metavar="N,N",
                   help="comma-separated agent counts N >= 2 (default: the scene's)")
    p.add_argument("--order", type=_list(int, 1, "a model order"), default=(None,),
                   metavar="1,2", help="comma-separated model orders: 1 (A-2), 2 (A-1) "
                   "(default: the scene's)")
    for name in ("kappa", "gamma", "mass"):
        p.add_argument(f"--{name}", type=_list(float, 0.0, name), default=(None,),
                       help=f"comma-separated {name} values (default: the scene's)")
    p.add_argument("--graph", type=_graphs, default=(None,), metavar="SPEC,SPEC",
                   help="communication graphs: complete, ring:K, k_nearest:K, random:P "
                        "(default: the scene's graph key)")
    p.add_argument("--normalise", choices=("size", "degree"),
                   help="graph weights kappa/N (size) or kappa/deg_i (degree)")
    p.add_argument("--settle", action="store_true",
                   help="an ensemble at an equilibrium other than consensus stops at a sample")
    p.add_argument("--integrator", "-i", metavar="NAME",
                   help="fixed-step integrator (default: the scene's); rkmk8 is DOP853's "
                        "8th-order tableau on a fixed step, by default the sample interval")
    p.add_argument("--dt", type=positive_float, help="step size")
    p.add_argument("--t-end", type=positive_float, help="override time.t_end")
    p.add_argument("--save", metavar="NPZ", help="save per-ensemble outcomes (npz)")
    p.add_argument("--figure", metavar="PNG", help="matched fraction against D0 (matplotlib)")
    p.add_argument("--bins", type=_int_in(1, 50), default=4,
                   help="D0 bins of the matched-fraction table (default 4)")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress lines")
    p.set_defaults(func=cmd_sweep)
    return p


def _graphs(text: str) -> tuple[str, ...]:
    """An argparse type: graph specs, each checked by ``core.sweep.graph_spec``."""
    from ..core.errors import ParameterError
    from ..core.sweep.scenes import graph_spec
    parts = tuple(text.split(","))
    for part in parts:
        try:
            graph_spec(part)
        except ParameterError as exc:
            raise argparse.ArgumentTypeError(str(exc).removeprefix("--graph: ")) from None
    return parts


def _d0_range(args: argparse.Namespace) -> tuple[float, float] | None:
    if args.d0 is None:
        return None
    if len(args.d0) != 2 or args.d0[0] > args.d0[1]:
        from ..core.errors import ParameterError
        raise ParameterError(f"--d0: expected LO,HI with LO <= HI, got "
                             f"{','.join(f'{v:g}' for v in args.d0)}")
    return (args.d0[0], args.d0[1])


def run_sweep(args: argparse.Namespace) -> list[CellResult]:
    """[(cell label, seeds, BatchResult)] for the parsed arguments (progress on stderr)."""
    from ..core.sweep import cell_scenes, grid, run_batch, template
    from ..core.sweep.scenes import cell_data, graph_text
    d0 = _d0_range(args)
    data = template(args.scene)
    if args.t_end is not None:
        data["time"] = dict(data.get("time") or {}, t_end=args.t_end)
    cells = grid(args.dimension, args.agents, args.order, args.kappa, args.gamma, args.mass,
                 args.graph, args.normalise)
    out = []
    for k, cell in enumerate(cells):
        scenes = cell_scenes(data, cell, args.ensembles, args.seed, d0)
        label = cell.label(scenes[0], graph_text(cell_data(data, cell)))
        progress = Progress(scenes[0].t_end, args.quiet)
        tag = (f"cell {k + 1}/{len(cells)} d={label['d']} N={label['N']} order={label['order']} "
               f"{label['graph']}")
        result = run_batch(scenes, args.integrator, args.dt, progress=_tagged(progress, tag),
                           settle=args.settle)
        progress.done()
        out.append((label, args.seed + np.arange(args.ensembles), result))
    return out


def _tagged(progress: Progress, tag: str) -> Callable[[float, float, str], None]:
    """A progress callback that names the cell."""
    def report(t: float, diameter: float, extra: str) -> None:
        progress(t, diameter, f"  {tag}{extra}")
    return report


def summary_row(label: dict[str, Any], result: BatchResult) -> list[Any]:
    """One row of the summary table (``HEADER``): how the cell's ensembles ended."""
    counts = [int(np.sum(result.outcome == o)) for o in ("matched", "antipodal", "twisted",
                                                         "other equilibrium", "too slow")]
    t_match = result.converged_at[~np.isnan(result.converged_at)]
    d0 = result.initial_rotation
    return [label["d"], label["N"], label["order"], f"{label['kappa']:g}", f"{label['gamma']:g}",
            f"{label['mass']:g}", label["graph"], len(d0), f"{d0.min():.2f}-{d0.max():.2f}",
            *counts,
            f"{np.median(t_match):g}" if len(t_match) else "-", f"{result.wall_time:.2f}"]


def twist_rows(results: list[CellResult]) -> list[list[Any]]:
    """Per ring cell, how its twisted ends wind: q counts (d = 2), else turns and loop class."""
    rows = []
    for label, _, r in results:
        if r.ring is None:
            continue
        twisted = r.outcome == "twisted"
        if label["d"] == 2:
            values, counts = np.unique(r.ring.winding[twisted], return_counts=True)
            what = ", ".join(f"q={int(v)}: {c}" for v, c in zip(values, counts))
        else:
            turns = np.rint(r.ring.turn[twisted])
            values, counts = np.unique(turns, return_counts=True)
            odd = int(np.sum(r.ring.loop_class[twisted] < 0))
            what = ", ".join(f"turn {int(v)}: {c}" for v, c in zip(values, counts))
            what += f" (not contractible: {odd})" if len(values) else ""
        rows.append([label["d"], label["N"], label["order"], label["graph"],
                     int(twisted.sum()), what or "-"])
    return rows


TWIST_HEADER = ["d", "N", "order", "graph", "twisted", "twists (winding q in d = 2; total turn "
                "and loop class in SO(d), d >= 3)"]


def d0_table(results: list[CellResult], bins: int) -> tuple[list[str], list[list[Any]]]:
    """(header, rows): matched / ensembles per D0 bin, one row per cell."""
    d0 = np.concatenate([r.initial_rotation for _, _, r in results])
    edges = np.linspace(0.0, max(float(d0.max()), 1e-12), bins + 1)
    header = ["d", "N", "order", "graph"] + [f"D0 {lo:.2f}-{hi:.2f}"
                                            for lo, hi in zip(edges, edges[1:])]
    rows = []
    for label, _, r in results:
        which = np.clip(np.searchsorted(edges, r.initial_rotation, side="right") - 1, 0,
                        bins - 1)
        matched = r.outcome == "matched"
        rows.append([label["d"], label["N"], label["order"], label["graph"]] +
                    [f"{int(matched[which == k].sum())}/{int((which == k).sum())}"
                     for k in range(bins)])
    return header, rows


def save_outcomes(results: list[CellResult], path: str) -> None:
    """Per-ensemble arrays over every cell (one row per ensemble) and per-cell diameters."""
    keys = ("cell", "seed", "d", "N", "order", "kappa", "gamma", "mass", "graph", "d0",
            "converged_at", "final_t", "final_matching", "stationarity", "order_parameter",
            "asymmetry", "outcome", "winding", "turn", "loop_class")
    cols: dict[str, list[np.ndarray]] = {k: [] for k in keys}
    data: dict[str, Any] = {}
    for k, (label, seeds, r) in enumerate(results):
        b = len(seeds)
        for key in ("d", "N", "order", "kappa", "gamma", "mass", "graph"):
            cols[key].append(np.full(b, label[key]))
        for key in ("winding", "turn", "loop_class"):        # nan off rings
            cols[key].append(np.full(b, np.nan) if r.ring is None else getattr(r.ring, key))
        cols["cell"].append(np.full(b, k))
        cols["seed"].append(seeds)
        cols["d0"].append(r.initial_rotation)
        for key in ("converged_at", "final_t", "final_matching", "stationarity",
                    "order_parameter", "asymmetry", "outcome"):
            cols[key].append(getattr(r, key))
        data[f"cell{k}_times"] = r.times
        data[f"cell{k}_diameters"] = r.diameters
    data.update({k: np.concatenate(v) for k, v in cols.items()})
    np.savez_compressed(path, **data)


def cmd_sweep(args: argparse.Namespace) -> int:
    """Run the sweep, print its tables; the npz and the figure if asked for."""
    save = writable_output(args.save, ".npz") if args.save else None
    figure = writable_output(args.figure, ".png") if args.figure else None
    results = run_sweep(args)
    print(format_table([summary_row(label, r) for label, _, r in results], HEADER))
    print("matched / ensembles by initial rotation diameter D0:")
    print(format_table(*reversed(d0_table(results, args.bins))))
    twists = twist_rows(results)
    if twists:
        print("twisted ends on rings:")
        print(format_table(twists, TWIST_HEADER))
    r0 = results[0][2]
    print(f"integrator {r0.method} dt = {r0.dt:g}; outcomes: matched = diameter < tolerance at "
          "a sample; antipodal / twisted = an equilibrium that is not consensus "
          "(pairs a half-turn apart / mean field S = 0, or on a ring every step turning by one "
          "angle); too slow = still moving (or converging) at t_end")
    for path, write, what in ((save, save_outcomes, "outcomes"), (figure, _figure, "figure")):
        if path:
            write(results, path)
            print(f"{what} saved to {path}")
    return 0


def _figure(results: list[CellResult], path: str) -> str:
    from ..figures import sweep_figure
    return sweep_figure(results, path)
