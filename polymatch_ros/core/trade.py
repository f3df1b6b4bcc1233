"""The trade on one scene: error against cost for every integrator that accepts it.

Every registered fixed-step method whose model orders include the scene's, at a ladder of
steps; the adaptive DOP853-Lie method and scipy's DOP853 (on the flattened model,
``core.stepping.flat``) at a ladder of tolerances.  Each run's error is the whole run's

    max over the sample times t_s, agents i and vertices a of |x^i_a(t_s) - x^i_a,ref(t_s)|,

x^i_a = xbar_i + s_i O_i r_a (F-1 scales where the group has them), against a tight
reference (adaptive at ``REF_TOL``) on one common time grid that every step of the ladder
divides, so fixed steps land on it and adaptive runs interpolate it.  The max over the run
matters: the spread decays like e^{-kappa t} (Theorem 4.2), so an error taken at t_end only
would flatter every method.  The reference's own error is estimated by a second run at
``CHECK_TOL``: errors near that floor are not resolved.

Cost: the wall time of each run (samples included), its right-hand-side evaluations and, for
a fixed-step method, its lockstep exchange rounds per step (``MethodInfo.rounds``): over ROS
a step costs that many message rounds, so rounds per simulated second = rounds / dt.

Time is bounded: a first cheap run of each solver kind (the probe) prices an evaluation, the
whole grid and the reference are estimated from it, the grid is trimmed (most expensive runs
first) to fit the budget, and a run that would overrun the deadline is stopped and the grid
with it (``TradeResult.notes`` says so).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from .errors import ParameterError, PolymatchError, StabilityError
from .stepping.integrators import METHODS
from .trade_runs import SCIPY_NAME, Output, OverBudget, Runs, max_vertex_error

if TYPE_CHECKING:
    from .scenes.scene import Scene

__all__ = ["DEFAULT_TOLERANCES", "Reference", "Row", "SCIPY", "Setting", "TradeResult",
           "fastest", "sample_times", "step_ladder", "trade"]

#: tolerances of the adaptive method and of scipy's DOP853 (rtol = atol)
DEFAULT_TOLERANCES = tuple(10.0 ** -k for k in range(3, 11))
#: fixed steps: the ladder's largest step divided by these
STEP_DIVISORS = (1, 2, 4, 10, 20, 40)
REF_TOL, CHECK_TOL = 1e-12, 1e-11
#: at most this many sample times (the errors are taken there)
MAX_SAMPLES = 201
SCIPY = SCIPY_NAME
#: DOP853 takes about (tol_1/tol_2)^(1/8) times the steps at a tighter tolerance
ADAPTIVE_EXPONENT = 1.0 / 8.0


@dataclass(frozen=True)
class Setting:
    """One solver at one setting: a fixed step (``kind`` fixed) or a tolerance."""

    solver: str          # a registered method, "adaptive" or SCIPY
    kind: str            # fixed | adaptive | scipy
    value: float         # dt, or rtol = atol

    @property
    def label(self) -> str:
        return f"dt {self.value:g}" if self.kind == "fixed" else f"tol {self.value:.0e}"

    def scene_keys(self) -> str | None:
        """The scene file's integrator keys for this setting (None: not a scene integrator)."""
        if self.kind == "fixed":
            return f"integrator: {{method: {self.solver}, dt: {yaml_number(self.value)}}}"
        if self.kind == "adaptive":
            return f"integrator: {{method: adaptive, tolerance: {yaml_number(self.value)}}}"
        return None


def yaml_number(x: float) -> str:
    """``x`` as a YAML float every parser reads as one: 0.05, 1.0e-08 (YAML 1.1 reads 1e-08 as
    text)."""
    text = f"{x:g}"
    mantissa, e, exponent = text.partition("e")
    return f"{mantissa}.0e{exponent}" if e and "." not in mantissa else text


@dataclass
class Row:
    """What one setting gave: status ok, refused (unstable), failed, or not run (budget)."""

    setting: Setting
    status: str = "not run"
    error: float | None = None
    wall: float | None = None
    evals: int | None = None
    steps: int | None = None
    cpu: float | None = None     # the CPU time of the thread that ran it (``Output.cpu``)
    predicted: float = 0.0       # seconds estimated before it ran
    detail: str = ""             # a failure's whole message (``status`` is cut for tables)

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    @property
    def rounds_per_step(self) -> int | None:
        """Lockstep exchange rounds per step (fixed-step methods; the others run centralised)."""
        s = self.setting
        return METHODS[s.solver].info.rounds if s.kind == "fixed" else None

    @property
    def rounds_per_simulated_second(self) -> float | None:
        rounds = self.rounds_per_step
        return None if rounds is None else rounds / self.setting.value

    def reaches(self, target: float) -> bool:
        return self.ok and self.error is not None and self.error <= target

    def to_dict(self) -> dict[str, Any]:
        s = self.setting
        return {"solver": s.solver, "kind": s.kind, "value": s.value, "status": self.status,
                "error": self.error, "wall": self.wall, "evals": self.evals,
                "steps": self.steps, "rounds_per_step": self.rounds_per_step,
                "rounds_per_simulated_second": self.rounds_per_simulated_second,
                "scene_keys": s.scene_keys()}


@dataclass(frozen=True)
class Reference:
    """The reference run and how far a looser one is from it (errors below are not resolved)."""

    tolerance: float
    wall: float
    floor: float


@dataclass
class TradeResult:
    """The measured grid, the reference, the time it took, and why runs were left out."""

    scene: str
    t_end: float
    target: float
    budget: float
    samples: int
    distributed: bool        # fixed steps as lockstep agents take them (graphs: centroids too)
    reference: Reference
    estimate: float          # seconds the probe predicted for the whole grid and reference
    elapsed: float = 0.0
    rows: list[Row] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def choice(self, over_ros: bool = False) -> Row | None:
        return fastest(self.rows, self.target, over_ros)

    def to_dict(self) -> dict[str, Any]:
        pick, ros = self.choice(), self.choice(over_ros=True)
        return {"scene": self.scene, "t_end": self.t_end, "target": self.target,
                "budget": self.budget, "samples": self.samples,
                "distributed": self.distributed,
                "reference": {"tolerance": self.reference.tolerance,
                              "wall": self.reference.wall, "floor": self.reference.floor},
                "estimate": self.estimate, "elapsed": self.elapsed,
                "rows": [r.to_dict() for r in self.rows], "notes": list(self.notes),
                "choice": None if pick is None else pick.to_dict(),
                "choice_over_ros": None if ros is None else ros.to_dict()}


def fastest(rows: Sequence[Row], target: float, over_ros: bool = False) -> Row | None:
    """The cheapest scene integrator whose error reaches ``target``, or None.

    Centralised: least wall time among fixed-step and adaptive runs (scipy's DOP853 is shown
    beside them but is no scene integrator).  Over ROS: fixed steps only (the adaptive method
    runs centralised), fewest lockstep rounds per simulated second, which is the least wall
    time per simulated second at any one round rate; of equal rounds, the less wall time
    (an agent's own work is part of each round).
    """
    kinds = ("fixed",) if over_ros else ("fixed", "adaptive")
    ok = [r for r in rows if r.reaches(target) and r.setting.kind in kinds]
    if not ok:
        return None
    if over_ros:
        return min(ok, key=lambda r: (r.rounds_per_simulated_second, r.wall))
    return min(ok, key=lambda r: r.wall or 0.0)


def step_ladder(scene: Scene) -> list[float]:
    """Fixed steps: H / 1, 2, 4, 10, 20, 40 with H the 1-2-5 number at most 4 x the scene's dt
    (``DEFAULT_DT`` when it names none) and at most t_end."""
    base = 4.0 * scene.integrator.step
    top = min(base, scene.t_end)
    decade = 10.0 ** math.floor(math.log10(top))
    h = max(m * decade for m in (1.0, 2.0, 5.0) if m * decade <= top * (1 + 1e-12))
    return [h / k for k in STEP_DIVISORS]


def sample_times(t_end: float, largest_step: float, limit: int = MAX_SAMPLES) -> np.ndarray:
    """0, c H, 2 c H, ... and t_end (c the least integer keeping at most ``limit`` times): every
    step H / k of the ladder lands on them."""
    c = max(1, math.ceil(t_end / largest_step / (limit - 1)))
    spacing = c * largest_step
    n = math.floor(t_end / spacing * (1 + 1e-12))
    times = spacing * np.arange(n + 1)
    times = times[times < t_end - 1e-9 * spacing]
    return np.append(times, t_end)


def candidates(scene: Scene, steps: Sequence[float],
               tolerances: Sequence[float]) -> list[Row]:
    """Every fixed-step method accepting the scene's model order at ``steps``; the adaptive
    method and scipy's DOP853 at ``tolerances``."""
    order = scene.model.order
    rows = [Row(Setting(name, "fixed", h)) for name, m in METHODS.items()
            if order in m.info.models for h in steps]
    rows += [Row(Setting("adaptive", "adaptive", tol)) for tol in tolerances]
    return rows + [Row(Setting(SCIPY, "scipy", tol)) for tol in tolerances]



#: (done, total, the row about to run, seconds since the start, seconds estimated in all)
ProgressFn = Callable[[int, int, Row, float, float], None]


class _Costs:
    """Seconds a setting will take, predicted from the runs so far (the probes first)."""

    def __init__(self, t_end: float) -> None:
        self.t_end = t_end
        self.per_eval: dict[str, float] = {}
        self.latest: dict[str, tuple[float, float]] = {}   # solver -> (tol, CPU s), last run


    def learn(self, row: Row) -> None:
        """Price ``row``'s setting by the CPU time of its run: on a busy machine its wall time
        holds what other processes took meanwhile, and a cheap probe stretched so would
        predict the tight runs (the reference) many times too dear; the deadline still stops
        a run that the machine makes overrun."""
        s = row.setting
        cost = row.cpu if row.cpu else row.wall
        if not row.ok or cost is None:
            return
        if s.kind == "fixed" and row.evals:
            self.per_eval[s.solver] = cost / row.evals
        elif s.kind != "fixed":      # runs go loosest first: the last is the tightest so far
            self.latest[s.solver] = (s.value, cost)

    def predict(self, s: Setting) -> float:
        if s.kind == "fixed":
            per_eval = self.per_eval.get(s.solver, max(self.per_eval.values(), default=0.0))
            steps = math.ceil(self.t_end / s.value - 1e-9)
            return METHODS[s.solver].info.stages * steps * per_eval
        tol, wall = self.latest.get(s.solver, (s.value, 0.0))
        return wall * (tol / s.value) ** ADAPTIVE_EXPONENT


def _attempt(runs: Runs, row: Row) -> Output | None:
    """Run one setting; its row says how it went (OverBudget passes through)."""
    s = row.setting
    try:
        if s.kind == "scipy":
            out = runs.scipy(s.value)
        elif s.kind == "fixed":
            out = runs.ours(s.solver, s.value, None)
        else:
            out = runs.ours("adaptive", None, s.value)
    except OverBudget:
        row.status = "stopped: over budget"
        raise
    except StabilityError as exc:
        limit = exc.limit
        row.status = "refused (unstable)" + (f": dt < {limit:.3g}" if limit else "")
        return None
    except (PolymatchError, ArithmeticError, ValueError) as exc:
        row.detail = " ".join(str(exc).split())
        row.status = "failed: " + row.detail[:80]
        return None
    row.status, row.wall, row.evals, row.steps = "ok", out.wall, out.evals, out.steps
    row.cpu = out.cpu
    return out


def _probes(rows: list[Row]) -> list[Row]:
    """The cheapest run of each kind: rkmk4 (or the first fixed method) at the largest step,
    the adaptive method and scipy at the loosest tolerance."""
    fixed = [r for r in rows if r.setting.kind == "fixed"]
    first = next((r for r in fixed if r.setting.solver == "rkmk4"), fixed[0] if fixed else None)
    picks = [] if first is None else [max((r for r in fixed if r.setting.solver ==
                                           first.setting.solver), key=lambda r: r.setting.value)]
    for kind in ("adaptive", "scipy"):
        same = [r for r in rows if r.setting.kind == kind]
        if same:
            picks.append(max(same, key=lambda r: r.setting.value))
    return picks


def _fit(rows: list[Row], seconds: float) -> tuple[list[Row], list[Row]]:
    """(kept, left out): the cheapest rows whose predicted seconds add up to ``seconds``."""
    kept: list[Row] = []
    total = 0.0
    ordered = sorted(rows, key=lambda r: r.predicted)
    for k, row in enumerate(ordered):
        if total + row.predicted > seconds:
            return kept, ordered[k:]
        kept.append(row)
        total += row.predicted
    return kept, []


def _left_out(rows: list[Row]) -> str:
    """'rkmk4 dt <= 0.01, adaptive tol <= 1e-09, ...': per solver, the loosest left out."""
    parts = []
    for solver in dict.fromkeys(r.setting.solver for r in rows):
        mine = [r.setting for r in rows if r.setting.solver == solver]
        top = max(mine, key=lambda s: s.value)
        parts.append(f"{solver} {top.label.split()[0]} <= {top.value:g}")
    return ", ".join(parts)


def _check_steps(steps: Sequence[float], times: np.ndarray) -> None:
    """Every step positive and landing on the sample times (so fixed runs are sampled there)."""
    spacing = times[1] - times[0] if len(times) > 2 else times[-1]
    for h in steps:
        if not (h > 0 and math.isfinite(h)):
            raise ParameterError(f"steps: must be positive numbers, got {h}")
        if abs(spacing / h - round(spacing / h)) > 1e-9 * spacing / h:
            raise ParameterError(f"steps: {h:g} does not divide the largest step "
                                 f"{max(steps):g} (the sample times are its multiples)")


class _Grid:
    """A trade in progress: the runs, the costs learnt, the deadline and what to report."""

    def __init__(self, scene: Scene, times: np.ndarray, budget: float,
                 distributed: bool) -> None:
        self.start = time.perf_counter()
        self.budget = budget
        self.runs = Runs(scene, times, self.start + budget, distributed)
        self.costs = _Costs(scene.t_end)
        self.reference: list[np.ndarray] = []

    def elapsed(self) -> float:
        return time.perf_counter() - self.start

    def left(self) -> float:
        return self.budget - self.elapsed()

    def reference_run(self) -> Reference:
        """Adaptive at REF_TOL and at CHECK_TOL; their distance is the floor of the errors."""
        try:
            ref = self.runs.ours("adaptive", None, REF_TOL)
            check = self.runs.ours("adaptive", None, CHECK_TOL)
        except OverBudget:
            raise ParameterError(
                f"the reference run (adaptive at tol {REF_TOL:g}) did not finish within the "
                f"budget of {self.budget:g} s; raise --budget or lower time.t_end") from None
        self.reference = ref.verts
        return Reference(REF_TOL, ref.wall, max_vertex_error(ref.verts, check.verts))

    def score(self, row: Row, out: Output | None) -> None:
        if out is not None:
            row.error = max_vertex_error(out.verts, self.reference)

    def predicted_reference(self) -> float:
        return sum(self.costs.predict(Setting("adaptive", "adaptive", tol))
                   for tol in (REF_TOL, CHECK_TOL))


def _run_grid(grid: _Grid, kept: list[Row], done: int, total: int, estimate: float,
              progress: ProgressFn | None) -> list[str]:
    """Run ``kept`` cheapest first while the budget allows; notes on what was not run."""
    order = sorted(kept, key=lambda r: r.predicted)
    for k, row in enumerate(order):
        row.predicted = grid.costs.predict(row.setting)
        if row.predicted > grid.left():
            for late in order[k:]:
                late.status = "not run (budget)"
            return [f"stopped before {row.setting.solver} {row.setting.label}: it would take "
                    f"~{row.predicted:.2g} s and {max(grid.left(), 0):.2g} s of the budget are "
                    f"left; {len(kept) - k} run(s) not done"]
        if progress is not None:
            progress(done + k, total, row, grid.elapsed(), estimate)
        try:
            grid.score(row, _attempt(grid.runs, row))
        except OverBudget:
            rest = order[k + 1:]
            for late in rest:
                late.status = "not run (budget)"
            return [f"stopped at the budget during {row.setting.solver} {row.setting.label}; "
                    f"{len(rest) + 1} run(s) not done"]
        grid.costs.learn(row)
    return []


#: a probe (the cheapest run of its kind) may take this share of the budget
PROBE_SHARE = 0.25


def _run_probes(grid: _Grid, probes: list[Row], rows: list[Row]) -> list[Output | None]:
    """Run each probe (twice: the first pays for imports and caches) within its share of the
    budget; a kind whose probe overruns is left out; the reference needs the adaptive one."""
    outputs: list[Output | None] = []
    deadline = grid.runs.deadline
    for row in probes:
        grid.runs.deadline = min(deadline, time.perf_counter() + PROBE_SHARE * grid.budget)
        try:
            _attempt(grid.runs, Row(row.setting))
            outputs.append(_attempt(grid.runs, row))
            grid.costs.learn(row)
        except OverBudget:
            outputs.append(None)
            row.status = f"stopped: over {PROBE_SHARE * grid.budget:.2g} s"
            for other in rows:
                if other.setting.solver == row.setting.solver and other is not row:
                    other.status = "not run (its cheapest setting overran)"
        finally:
            grid.runs.deadline = deadline
    adaptive = next(r for r in probes if r.setting.kind == "adaptive")
    if adaptive.status.startswith("stopped"):
        raise ParameterError(
            f"the adaptive method at tol {adaptive.setting.value:g} takes longer than "
            f"{PROBE_SHARE:.0%} of the budget, and the reference is a tighter run of it; raise "
            "--budget or lower time.t_end (a stiff scene? `polymatch explain SCENE`)")
    if not adaptive.ok:
        raise PolymatchError(f"no reference (the adaptive method at tol "
                             f"{adaptive.setting.value:g} fails): {adaptive.detail}")
    return outputs


def trade(scene: Scene, target: float, budget: float, *, distributed: bool = False,
          steps: Sequence[float] | None = None,
          tolerances: Sequence[float] = DEFAULT_TOLERANCES,
          notice: Callable[[str], None] | None = None,
          progress: ProgressFn | None = None) -> TradeResult:
    """Measure the trade on ``scene`` within ``budget`` seconds (see the module docstring).

    ``notice(text)`` gets the estimate and what the budget leaves out as they are known;
    ``progress(done, total, row, elapsed, estimate)`` is called before each run.
    """
    if not (target > 0 and math.isfinite(target)):
        raise ParameterError(f"target error: must be a positive number, got {target}")
    if not (budget > 0 and math.isfinite(budget)):
        raise ParameterError(f"budget: must be a positive number of seconds, got {budget}")
    steps = list(steps) if steps is not None else step_ladder(scene)
    times = sample_times(scene.t_end, max(steps))
    _check_steps(steps, times)
    say = notice or (lambda text: None)
    from scipy.integrate import solve_ivp  # noqa: F401 -- imported before the clock starts

    from .stepping import adaptive  # noqa: F401
    grid = _Grid(scene, times, budget, distributed)
    rows = candidates(scene, steps, tolerances)
    probes = _probes(rows)
    outputs = _run_probes(grid, probes, rows)
    rest = [r for r in rows if r not in probes and r.status == "not run"]
    for row in rest:
        row.predicted = grid.costs.predict(row.setting)
    ref_cost = grid.predicted_reference()
    if ref_cost > grid.left():
        raise ParameterError(f"the reference run alone would take ~{ref_cost:.2g} s, more than "
                             f"the {max(grid.left(), 0):.2g} s the budget leaves; raise "
                             "--budget or lower time.t_end")
    kept, dropped = _fit(rest, grid.left() - ref_cost)
    estimate = grid.elapsed() + ref_cost + sum(r.predicted for r in kept)
    notes = [f"the grid is trimmed to fit the budget: {len(kept) + len(probes)} of "
             f"{len(rows)} runs; left out: {_left_out(dropped)}"] if dropped else []
    for row in dropped:
        row.status = "not run (budget)"
    say(f"{len(kept) + len(probes)} runs and the reference, about {estimate:.2g} s (budget "
        f"{budget:.0f} s)"
        + ("; " + notes[0] if notes else ""))
    reference = grid.reference_run()
    if target < 10 * reference.floor:
        notes.append(f"the target {target:g} is near the reference's floor ({reference.floor:.1e}"
                     "): errors that small are not resolved")
    for row, out in zip(probes, outputs):
        grid.score(row, out)
    notes += _run_grid(grid, kept, len(probes), len(kept) + len(probes), estimate, progress)
    notes += _retime(grid, rows, target)
    return TradeResult(scene.name, scene.t_end, target, budget, len(times), distributed,
                       reference, estimate, grid.elapsed(), rows, notes)


#: the runs within this factor of the fastest that reaches the target are timed again
CONTENDERS = 2.0
RETIMES = 2


def _retime(grid: _Grid, rows: list[Row], target: float) -> list[str]:
    """Time the contenders for the recommendation again (best of 1 + RETIMES) while the budget
    allows: one run each is at the mercy of the machine's load."""
    pick = fastest(rows, target)
    if pick is None or pick.wall is None:
        return []
    best = pick.wall
    contenders = [r for r in rows if r.reaches(target) and r.wall is not None
                  and r.setting.kind != "scipy" and r.wall <= CONTENDERS * best]
    timed = 0
    note = [f"{len(contenders)} run(s) within {CONTENDERS:g}x of the fastest that reaches the "
            f"target are timed again (up to {RETIMES} more times; wall = best)"]
    for row in sorted(contenders, key=lambda r: r.wall or 0.0):
        for _ in range(RETIMES):
            if 2 * (row.wall or 0.0) > grid.left():
                break
            again = Row(row.setting)
            try:
                _attempt(grid.runs, again)
            except OverBudget:
                return note + [f"the budget ran out after {timed} re-timing(s)"]
            if again.ok and again.wall is not None:
                row.wall = min(row.wall or again.wall, again.wall)
                timed += 1
    return note if timed else []
