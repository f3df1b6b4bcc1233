"""The figure of `polymatch trade --figure`: error against wall time, per solver."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..figures import FigurePath, _pyplot

if TYPE_CHECKING:
    from ..core.trade import TradeResult
    from ..ros.supervisor.round_rate import RoundRate


def trade_figure(result: TradeResult, rate: RoundRate | None, path: FigurePath) -> FigurePath:
    """Max vertex error against centralised wall time (and, with a round rate, against wall
    time per simulated second over ROS), one line per solver, the target as a line."""
    plt = _pyplot()
    panels = 2 if rate is not None else 1
    fig, axes = plt.subplots(1, panels, figsize=(6.0 * panels, 4.4), squeeze=False)
    solvers = list(dict.fromkeys(r.setting.solver for r in result.rows))
    for k, solver in enumerate(solvers):
        rows = [r for r in result.rows if r.setting.solver == solver and r.ok and r.error]
        if not rows:
            continue
        kind = rows[0].setting.kind
        style = {"fixed": "o-", "adaptive": "D-", "scipy": "x:"}[kind]
        colour = "k" if kind == "adaptive" else f"C{k % 10}"
        errors = [r.error for r in rows]
        axes[0][0].loglog([r.wall for r in rows], errors, style, color=colour, ms=4,
                          label=solver)
        if rate is not None and kind == "fixed":
            walls = [rate.wall_per_simulated_second(r.rounds_per_step or 0, r.setting.value)
                     for r in rows]
            axes[0][1].loglog(walls, errors, style, color=colour, ms=4, label=solver)
    axes[0][0].set_xlabel("wall s (centralised)")
    axes[0][0].set_title(f"{result.scene}: max vertex error over the run", fontsize=10)
    if rate is not None:
        axes[0][1].set_xlabel(f"wall s per simulated s over ROS (lockstep, "
                              f"{rate.rounds_per_second:.0f} rounds/s)")
        axes[0][1].set_title("fixed steps over ROS: rounds per step / dt / rounds per s",
                             fontsize=10)
    for ax in axes[0]:
        ax.axhline(result.target, color="r", lw=0.8, ls="--", label="target")
        ax.set_ylabel("max vertex error")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
