"""Paper-style snapshot figures (Figures 1-3) rendered to PNG; matplotlib is an optional extra."""

from __future__ import annotations

import os
from collections.abc import Sequence
from types import ModuleType
from typing import TYPE_CHECKING, Any, TypeVar

import numpy as np

from .core.errors import PolymatchError
from .core.metrics import vertices

if TYPE_CHECKING:
    from .core.model import Group, State
    from .core.scenes.scene import Scene
    from .core.stepping.simulate import Trajectory
    from .core.sweep.run import BatchResult

#: where a figure goes: a file name, returned as it was given
FigurePath = TypeVar("FigurePath", str, os.PathLike[str])

COLOURS = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#17becf"]


def _pyplot() -> ModuleType:
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise PolymatchError(
            "figures need matplotlib: pip install 'polymatch_ros[plot]'") from None
    return plt


def _placed_vertices(scene: Scene, state: State) -> list[tuple[Group, np.ndarray]]:
    """Per group: (group, (N, n_a, d) vertices xbar_i + s_i O_i r_a in absolute coordinates)."""
    model = scene.model
    placed = []
    for g, gs in zip(model.groups, state.groups):
        assert gs is not None  # a stored state has every group
        placed.append((g, vertices(gs.x + scene.origin, model.rotations.to_matrices(gs.rot),
                                   g.reference, g.scales)))
    return placed


def polytope_segments(scene: Scene, state: State) -> list[list[np.ndarray]]:
    """Per group: list of (2, d) edge segments in absolute coordinates."""
    return [[np.array([v[a], v[b]]) for v in verts for a, b in g.edges]
            for g, verts in _placed_vertices(scene, state)]


def first_vertices(scene: Scene, state: State) -> list[np.ndarray]:
    """Per group: (N, d) positions of every polytope's vertex 0 (the vertex correspondence)."""
    return [verts[:, 0] for _, verts in _placed_vertices(scene, state)]


def snapshot_figure(
    traj: Trajectory, path: FigurePath, times: Sequence[float] | None = None
) -> FigurePath:
    """Save a 1 x k row of snapshots (t = 0, 3, 6, 12 by default) of a trajectory to ``path``."""
    plt = _pyplot()
    scene = traj.scene
    times = list(scene.snapshots if times is None else times)
    have = np.array(traj.times)
    picks = []
    for t in times:
        k = int(np.argmin(np.abs(have - t)))
        if abs(have[k] - t) <= 1e-6 * max(1.0, t) + 1e-9 and traj.states:
            picks.append((t, traj.states[k], traj.metrics[k].diameter if traj.metrics else None))
    if not picks:
        raise PolymatchError(
            "no stored states at the snapshot times; simulate with those sample times")
    fig = plt.figure(figsize=(3.2 * len(picks), 3.4))
    _draw_snapshots(fig, scene, picks, (1, len(picks)))
    title = f"{scene.name}: {scene.description}" if scene.description else scene.name
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _draw_snapshots(fig: Any, scene: Scene, picks: Sequence[tuple[float, State, float | None]],
                    grid: tuple[int, int]) -> None:
    """One axis per (t, state, diameter) in the first row of a ``grid`` (rows, columns) of
    ``fig``: every polytope's edges, vertex 0 marked (the correspondence), common limits."""
    dim = scene.dim
    all_pts = np.concatenate([np.concatenate(s).reshape(-1, dim)
                              for _, st, _ in picks for s in polytope_segments(scene, st) if s])
    lo, hi = all_pts.min(axis=0), all_pts.max(axis=0)
    centre, half = (lo + hi) / 2, max(np.max(hi - lo) / 2, 1e-9) * 1.05
    for k, (t, st, diam) in enumerate(picks):
        if dim == 2:
            ax = fig.add_subplot(*grid, k + 1)
        else:
            ax = fig.add_subplot(*grid, k + 1, projection="3d")
        groups = zip(polytope_segments(scene, st), first_vertices(scene, st))
        for gi, (segs, first) in enumerate(groups):
            colour = COLOURS[gi % len(COLOURS)]
            for seg in segs:
                ax.plot(*seg[:, :3].T, color=colour, lw=1.0, alpha=0.85)
            # vertex a = 0: matched vertex for vertex
            ax.plot(*first[:, :3].T, "o", color=colour, ms=2.5)
        for a in range(min(dim, 3)):
            getattr(ax, "set_" + "xyz"[a] + "lim")(centre[a] - half, centre[a] + half)
        if dim == 2:
            ax.set_aspect("equal")
        title = f"t = {t:g}"
        if diam is not None:
            title += f"\nmatching diameter {diam:.2e}"
        ax.set_title(title, fontsize=9)
        ax.tick_params(labelsize=7)


def recording_figure(t: np.ndarray, curves: Sequence[tuple[str, np.ndarray]], path: FigurePath,
                     scene: Scene | None = None,
                     snapshots: Sequence[tuple[float, State, float | None]] = (),
                     title: str = "", note: str = "") -> FigurePath:
    """A recorded run: its snapshots (if any, with the scene) above its diameters against
    simulated time ``t`` (``curves``: (label, values), log scale; ``note`` under the plot's
    title)."""
    plt = _pyplot()
    columns = max(1, len(snapshots))
    rows = 2 if snapshots and scene is not None else 1
    fig = plt.figure(figsize=(max(6.4, 3.2 * columns), 3.4 * rows))
    if rows == 2:
        assert scene is not None  # snapshots are drawn with the scene only
        _draw_snapshots(fig, scene, snapshots, (2, columns))
    ax = fig.add_subplot(rows, 1, rows)
    for k, (label, values) in enumerate(curves):
        ax.semilogy(t, np.maximum(values, 1e-300), ("-", "--", ":", "-.")[k % 4], lw=1.2,
                    label=label)
    for when, _, _ in snapshots:
        ax.axvline(when, color="grey", lw=0.6, alpha=0.6)
    ax.set_xlabel("simulated time t")
    ax.set_ylabel("diameter")
    ax.legend(fontsize=7)
    if note:
        ax.set_title(note, fontsize=9)
    ax.tick_params(labelsize=7)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def sweep_figure(
    results: Sequence[tuple[dict[str, Any], Any, BatchResult]], path: FigurePath, bins: int = 8
) -> FigurePath:
    """Matched fraction against the initial rotation diameter D0, one line per sweep cell."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(5.2, 3.6))
    d0_all = np.concatenate([r.initial_rotation for _, _, r in results])
    edges = np.linspace(d0_all.min(), max(d0_all.max(), d0_all.min() + 1e-9), bins + 1)
    centres = 0.5 * (edges[1:] + edges[:-1])
    for k, (label, _, r) in enumerate(results):
        which = np.clip(np.searchsorted(edges, r.initial_rotation, side="right") - 1, 0, bins - 1)
        matched = r.outcome == "matched"
        frac = [matched[which == i].mean() if np.any(which == i) else np.nan
                for i in range(bins)]
        ax.plot(centres, frac, "o-", color=COLOURS[k % len(COLOURS)], ms=3, lw=1.0,
                label=f"d={label['d']} N={label['N']} order {label['order']}")
    ax.axvline(1.0, color="grey", lw=0.8, ls="--")
    ax.set_xlabel("initial rotation diameter D0 = max |O_i - O_j|_F")
    ax.set_ylabel("fraction matched")
    ax.set_ylim(-0.05, 1.05)
    ax.legend(fontsize=7)
    ax.set_title("which initial states match (D0 < 1: Theorem 4.2)", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
