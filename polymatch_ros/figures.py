"""Paper-style snapshot figures (Figures 1-3) rendered to PNG; matplotlib is an optional extra."""

import numpy as np

from .core.errors import PolymatchError

COLOURS = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#17becf"]


def _pyplot():
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise PolymatchError(
            "figures need matplotlib: pip install 'polymatch_ros[plot]'") from None
    return plt


def polytope_segments(scene, state):
    """Per group: list of (2, d) edge segments in absolute coordinates."""
    model = scene.model
    out = []
    for g, gs in zip(model.groups, state.groups):
        mats = model.rotations.to_matrices(gs.rot)
        scales = np.ones(len(mats)) if g.scales is None else g.scales
        body = scales[:, None, None] * np.einsum("nij,aj->nai", mats, g.reference)
        verts = (gs.x + scene.origin)[:, None, :] + body
        segs = [np.array([v[a], v[b]]) for v in verts for a, b in g.edges]
        out.append(segs)
    return out


def first_vertices(scene, state):
    """Per group: (N, d) positions of every polytope's vertex 0 (the vertex correspondence)."""
    model = scene.model
    out = []
    for g, gs in zip(model.groups, state.groups):
        mats = model.rotations.to_matrices(gs.rot)
        scales = np.ones(len(mats)) if g.scales is None else g.scales
        out.append(gs.x + scene.origin + scales[:, None] * (mats @ g.reference[0]))
    return out


def snapshot_figure(traj, path, times=None):
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
    dim = scene.dim
    fig = plt.figure(figsize=(3.2 * len(picks), 3.4))
    all_pts = np.concatenate([np.concatenate(s).reshape(-1, dim)
                              for _, st, _ in picks for s in polytope_segments(scene, st) if s])
    lo, hi = all_pts.min(axis=0), all_pts.max(axis=0)
    centre, half = (lo + hi) / 2, max(np.max(hi - lo) / 2, 1e-9) * 1.05
    for k, (t, st, diam) in enumerate(picks):
        if dim == 2:
            ax = fig.add_subplot(1, len(picks), k + 1)
        else:
            ax = fig.add_subplot(1, len(picks), k + 1, projection="3d")
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
    title = f"{scene.name}: {scene.description}" if scene.description else scene.name
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
