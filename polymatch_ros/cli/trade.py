"""`polymatch trade SCENE`: error against cost of every integrator on the user's own scene.

    polymatch trade SCENE [--target-error E] [--budget S] [--over-ros] [--figure PNG] [--json]

The centralised measurement is ``core.trade`` (every integrator that accepts the scene at a
ladder of steps, the adaptive method and scipy's DOP853 at a ladder of tolerances, the whole
run's max vertex error against a tight reference); ``--over-ros`` adds the lockstep round rate
of a short real run (``ros.supervisor.round_rate``), so each fixed-step setting's wall time per
simulated second over ROS.  It ends with the fastest setting that reaches the target error, as
the scene keys to write.  Exit 0 with a recommendation, 3 when no setting reaches the target,
2 for bad input.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from typing import TYPE_CHECKING, Any, TextIO

from ..console import format_table, positive_float, writable_output
from ..core.errors import ParameterError
from ..core.scenes.preflight import check_run
from ..core.scenes.scene import Scene, load_scene, resolve_scene_path
from ..core.trade import MAX_SAMPLES, Row, TradeResult, trade

if TYPE_CHECKING:
    from ..ros.supervisor.round_rate import RoundRate

#: no setting reaches the target error
EXIT_NO_CHOICE = 3
DEFAULT_BUDGET = 60.0
DEFAULT_TARGET = 1e-6
#: --over-ros: at least this much of the budget for the centralised grid
MIN_GRID_SECONDS = 10.0


class RunProgress:
    """One updating line on a terminal (a line every few seconds otherwise), on stderr."""

    def __init__(self, quiet: bool, stream: TextIO | None = None) -> None:
        self.quiet, self.stream = quiet, sys.stderr if stream is None else stream
        self.tty = self.stream.isatty()
        self.last = -1e9

    def __call__(self, done: int, total: int, row: Row, elapsed: float,
                 estimate: float) -> None:
        now = time.monotonic()
        if self.quiet or (not self.tty and now - self.last < 2.0):
            return
        self.last = now
        text = (f"trade: run {done + 1}/{total}: {row.setting.solver} {row.setting.label}, "
                f"{elapsed:.1f} s of about {estimate:.2g} s")
        self.stream.write("\r" + text.ljust(72) if self.tty else text + "\n")
        self.stream.flush()

    def done(self) -> None:
        if self.tty and not self.quiet and self.last > -1e9:
            self.stream.write("\n")

    def say(self, text: str) -> None:
        if not self.quiet:
            self.stream.write(f"trade: {text}\n")
            self.stream.flush()


def _cells(row: Row, rate: RoundRate | None) -> list[Any]:
    s = row.setting
    error = f"{row.error:.2e}" if row.ok and row.error is not None else row.status
    rounds = row.rounds_per_step
    cells = [s.solver, s.label, error,
             "-" if row.wall is None else f"{row.wall:.3g}",
             "-" if row.evals is None else row.evals,
             "-" if rounds is None else rounds]
    if rate is not None:
        cells.append("-" if rounds is None else
                     f"{rate.wall_per_simulated_second(rounds, s.value):.3g}")
    return cells


def table(result: TradeResult, rate: RoundRate | None) -> str:
    """Every setting: error, wall, evaluations, rounds per step [, ROS wall per simulated s]."""
    header = ["solver", "dt / tol", f"max vertex error ({result.samples} times)", "wall s",
              "evaluations", "rounds/step"]
    if rate is not None:
        header.append("ROS wall s per simulated s")
    return format_table([_cells(r, rate) for r in result.rows], header)


def recommendation(result: TradeResult, over_ros: bool, rate: RoundRate | None) -> list[str]:
    """The lines that end the report: the choice as scene keys, or that none reaches it."""
    lines = []
    pick = result.choice()
    if pick is not None:
        lines.append(f"fastest centralised: {pick.setting.scene_keys()}  (error "
                     f"{pick.error:.2e} <= {result.target:g}, wall {pick.wall:.3g} s)")
    if over_ros:
        ros = result.choice(over_ros=True)
        if ros is not None and rate is not None:
            wall = rate.wall_per_simulated_second(ros.rounds_per_step or 0, ros.setting.value)
            lines.append(f"fastest over ROS (lockstep): {ros.setting.scene_keys()}  (error "
                         f"{ros.error:.2e}, {ros.rounds_per_simulated_second:g} rounds per "
                         f"simulated s, about {wall:.3g} wall s per simulated s)")
        pick = ros
    if pick is None:
        where = "over ROS" if over_ros else "centralised"
        lines.append(f"no setting {where} reaches the target error {result.target:g} within "
                     "the budget (see the table); raise --target-error or --budget")
    return lines


def _measured_setting(result: TradeResult, scene: Scene) -> tuple[str, float]:
    """The fixed-step setting the lockstep run is measured with: the choice over ROS, else the
    most accurate fixed-step run, else the scene's own distributed plan."""
    pick = result.choice(over_ros=True)
    if pick is None:
        fixed = [r for r in result.rows if r.ok and r.setting.kind == "fixed"]
        pick = min(fixed, key=lambda r: r.error or 0.0) if fixed else None
    if pick is not None:
        return pick.setting.solver, pick.setting.value
    from ..core.stepping.simulate import choose_numerics
    p = choose_numerics(scene, distributed=True)
    assert p.dt is not None  # a distributed plan takes fixed steps
    return p.name, p.dt


def measure_over_ros(path: str, scene: Scene, result: TradeResult, seconds: float,
                     say: Any) -> RoundRate:
    """The lockstep round rate of a short real run of the scene, bounded by ``seconds``."""
    from ..ros.supervisor.round_rate import DEFAULT_ROUNDS, measure_round_rate

    method, dt = _measured_setting(result, scene)
    say(f"lockstep run: {scene.model.n_agents} agents, {method} dt {dt:g}, about "
        f"{DEFAULT_ROUNDS} rounds (limit {seconds:.0f} s)")
    rate = measure_round_rate(path, method, dt, DEFAULT_ROUNDS, timeout=seconds)
    say(f"lockstep: {rate.rounds_per_second:.1f} rounds/s (mean of {rate.processes} agent "
        f"processes, slowest {rate.slowest:.1f}; {rate.rounds} rounds, {rate.wall:.1f} s with "
        "start-up" + (")" if rate.finished else "; cut at its time limit)"))
    return rate


def _budgets(args: argparse.Namespace, scene: Scene, say: Any) -> tuple[float, float]:
    """(seconds for the centralised grid, seconds reserved for the lockstep run)."""
    if not args.over_ros:
        return args.budget, 0.0
    from ..ros.supervisor.round_rate import estimate_seconds

    ros = estimate_seconds(scene.model.n_agents)
    if args.budget < ros + MIN_GRID_SECONDS:
        raise ParameterError(f"--budget {args.budget:g}: --over-ros needs about {ros:.0f} s for "
                             f"its lockstep run of {scene.model.n_agents} agents (on this "
                             f"machine's load) and the grid some more; give --budget "
                             f"{ros + 3 * MIN_GRID_SECONDS:.0f} or more")
    say(f"about {ros:.0f} s of the budget are kept for the lockstep run")
    return args.budget - ros, ros


def as_json(result: TradeResult, rate: RoundRate | None, code: int) -> str:
    """The whole result as JSON (rows, reference, choices, the lockstep rate)."""
    data = result.to_dict()
    data["ros"] = None if rate is None else rate.to_dict()
    if rate is not None:
        for d, row in zip(data["rows"], result.rows):
            rounds = row.rounds_per_step
            d["ros_wall_per_simulated_second"] = None if rounds is None else \
                rate.wall_per_simulated_second(rounds, row.setting.value)
    data["exit_code"] = code
    return json.dumps(data, indent=1)


def cmd_trade(args: argparse.Namespace) -> int:
    """Measure, print the table and the recommendation; exit 3 when nothing reaches the target."""
    figure = writable_output(args.figure, ".png") if args.figure else None
    path = resolve_scene_path(args.scene)
    scene = load_scene(path)
    with warnings.catch_warnings():      # the scene's own dt/tolerance is no concern here
        warnings.simplefilter("ignore")
        check_run(scene, "adaptive", kept_samples=MAX_SAMPLES)
    out = RunProgress(args.quiet or args.json)
    start = time.monotonic()
    grid_budget, ros_seconds = _budgets(args, scene, out.say)
    left = grid_budget - (time.monotonic() - start)
    if left <= 0:
        raise ParameterError(f"--budget {args.budget:g}: spent before the first run; give "
                             f"--budget a few seconds at least")
    result = trade(scene, args.target_error, left, distributed=args.over_ros, notice=out.say,
                   progress=out)
    out.done()
    rate = None
    if args.over_ros:      # the time left, or half the estimate (a rate needs a few rounds)
        left = args.budget - (time.monotonic() - start)
        rate = measure_over_ros(path, scene, result, max(left, 0.5 * ros_seconds), out.say)
    code = 0 if result.choice(over_ros=args.over_ros) is not None else EXIT_NO_CHOICE
    if args.json:
        print(as_json(result, rate, code))
    else:
        _print_report(result, rate, args.over_ros, scene)
    if figure:
        from .trade_figure import trade_figure
        trade_figure(result, rate, figure)
        print(f"figure saved to {figure}", file=sys.stderr if args.json else sys.stdout)
    return code


def _print_report(result: TradeResult, rate: RoundRate | None, over_ros: bool,
                  scene: Scene) -> None:
    m = scene.model
    ref = result.reference
    print(f"scene {scene.name}: {m.n_agents} agents, d = {m.dim}, "
          f"{'first' if m.order == 1 else 'second'} order, t_end = {scene.t_end:g}; error = "
          f"max vertex error over {result.samples} sample times against adaptive at tol "
          f"{ref.tolerance:g} ({ref.wall:.2g} s; a run at 10x that tolerance is "
          f"{ref.floor:.1e} from it: errors near that are not resolved)")
    if result.distributed:
        print("fixed steps as the lockstep agents take them (on a graph: the centroids "
              "integrated with the stages)")
    print(table(result, rate))
    print(f"measured in {result.elapsed:.1f} s (estimate {result.estimate:.2g} s, the grid's "
          f"budget {result.budget:.0f} s)")
    if rate is not None:
        print(f"ROS column: rounds per step / dt / {rate.rounds_per_second:.1f} rounds/s, the "
              f"rate measured with {rate.method} dt {rate.dt:g} ({rate.processes} agent "
              "processes); a round costs mostly the exchange, so every method is given that rate")
    for note in result.notes:
        print(f"note: {note}")
    for line in recommendation(result, over_ros, rate):
        print(line)


def add_parser(sub: argparse._SubParsersAction) -> None:
    """The ``trade`` subcommand."""
    p = sub.add_parser(
        "trade", help="error against cost of every integrator on a scene; the fastest setting "
                      "that reaches a target error",
        epilog="exit codes: 0 a setting reaches the target error, 3 none does (within the "
               "budget), 2 bad input")
    p.add_argument("scene", help="scene file or shipped scene name")
    p.add_argument("--target-error", type=positive_float, default=DEFAULT_TARGET,
                   metavar="E", help="max vertex error over the run to reach "
                                     f"(default {DEFAULT_TARGET:g})")
    p.add_argument("--budget", type=positive_float, default=DEFAULT_BUDGET, metavar="SECONDS",
                   help=f"wall-clock seconds for the whole measurement (default "
                        f"{DEFAULT_BUDGET:g}); the grid is trimmed to fit (start-up and the "
                        "figure come on top)")
    p.add_argument("--over-ros", action="store_true",
                   help="also measure the lockstep round rate in a short real run: wall time "
                        "per simulated second over ROS")
    p.add_argument("--figure", metavar="PNG", help="error against wall time (needs matplotlib)")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress line")
    p.set_defaults(func=cmd_trade)
