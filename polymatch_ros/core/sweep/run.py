"""Sweeps: many independent ensembles of one scene kind, integrated together (``core.batch``).

``run_batch(scenes)`` integrates B single-group scenes that differ only in their initial
states with the scene's fixed-step integrator (or another registered one, or rkmk8 of
``chart_rk``, by default at the sample interval), all B along one batch axis, and records
per ensemble what ``simulate(scene, stop_when_converged=True)`` would: the first sample
time at which the matching diameter is below the scene's tolerance (Theorems 4.1/4.2),
the state there (or at t_end), and the diameters at every sample.  Ensembles that have
matched leave the batch (their rows are dropped), so the batch shrinks as it converges.

Ensembles that do not match by t_end are classified from the metrics of their end state
(``classify``): an equilibrium that is not consensus (the rotation field max_i |W_i| is
~0, ``metrics.stationarity``) is *antipodal* when every pair O_i^T O_j is symmetric (each
pair at consensus or a half-turn apart) with a non-zero mean field, *twisted* when the
mean field S = sum_k O_k vanishes (splay/twisted states, where the torque is zero because
S is); anything still moving is *too slow* (t_end too short for it).
"""

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import ParameterError
from ..integrators import check_stability
from ..model import State
from ..scene import Scene
from ..simulate import Plan, plan, prepare
from ..solver import RUNNING
from . import chart_rk
from .batch import (
    BatchSystem,
    batch_metrics,
    ensemble_rows,
    equilibrium_measures,
    stack_states,
    take_ensembles,
)

OUTCOMES = ("matched", "antipodal", "twisted", "other equilibrium", "too slow")
#: an end state is an equilibrium when max_i |W_i| < STILL * kappa / gamma
STILL = 1e-6
#: |mean O| / sqrt(d) below this: the mean field vanishes (a twisted/splay state)
NO_MEAN_FIELD = 1e-3
#: max_{i,j} |O_i^T O_j - O_j^T O_i| below this: every pair at consensus or a half-turn apart
SYMMETRIC = 1e-3
#: fixed-step methods a batch runs besides the registry's (``chart_rk``, built on first use)
BATCH_METHODS = {"rkmk8": "RKMK8"}


@dataclass
class BatchResult:
    """Per ensemble (arrays of length B, in the order of the scenes) and the run's cost."""

    times: np.ndarray              # (T,) sample times
    diameters: np.ndarray          # (T, B) matching diameter; nan after the ensemble matched
    initial_rotation: np.ndarray   # D0 = max_{i,j} |O_i - O_j|_F at t = 0
    converged_at: np.ndarray       # first sample with diameter < tolerance; nan: never
    final_t: np.ndarray
    final_x: np.ndarray            # (B, N, d) centroids (scene offsets) at final_t
    final_rot: np.ndarray          # (B, N, d, d) rotation matrices at final_t
    final_matching: np.ndarray
    stationarity: np.ndarray       # nan for matched ensembles
    order_parameter: np.ndarray
    asymmetry: np.ndarray
    outcome: np.ndarray            # OUTCOMES entries
    method: str
    dt: float
    steps: int
    rhs_evals: int                 # of the batch (each evaluation serves every live ensemble)
    wall_time: float


def check_batch(scenes: Sequence) -> None:
    """Refuse scenes that cannot share one batch (ParameterError: exit 2)."""
    if not scenes:
        raise ParameterError("a sweep needs at least one ensemble")
    first = scenes[0]
    m0 = first.model
    if len(m0.groups) != 1 or m0.groups[0].scales is not None or m0.groups[0].graph is not None:
        raise ParameterError(f"{first.name}: a sweep takes scenes with one congruent group on "
                             "the complete graph")
    key = (m0.dim, m0.order, m0.kappa, m0.gamma, m0.mass, m0.n_agents, first.t_end,
           first.tolerance, first.integrator, m0.rotations.name)
    for s in scenes[1:]:
        m = s.model
        if (m.dim, m.order, m.kappa, m.gamma, m.mass, m.n_agents, s.t_end, s.tolerance,
                s.integrator, m.rotations.name) != key or \
                not np.array_equal(m.groups[0].reference, m0.groups[0].reference):
            raise ParameterError(f"{s.name}: ensembles of one batch must share the model, "
                                 "shape, integrator and times")


def batch_plan(scene: Scene, method: str | None = None, dt: float | None = None) -> Plan:
    """The batch's fixed-step integrator: ``simulate.plan``'s, or one of BATCH_METHODS.

    A BATCH_METHODS method steps by the scene's smallest sample interval unless ``dt`` is
    given (its steps end on the samples, where ensembles are tested and leave).
    """
    if method not in BATCH_METHODS:
        plan_ = plan(scene, method, dt)
        if plan_.dt is None:
            raise ParameterError("a sweep takes fixed-step integrators (the adaptive one would "
                                 "share one step size between independent ensembles)")
        return plan_
    step = dt if dt is not None else sample_interval(scene)
    if not (step > 0 and math.isfinite(step)):
        raise ParameterError(f"dt must be a positive number, got {step}")
    step = min(step, scene.t_end)
    meth = getattr(chart_rk, BATCH_METHODS[method])
    check_stability(meth, scene.model, step)
    return Plan(meth, step, None, "chosen explicitly")


def sample_interval(scene: Scene) -> float:
    """The smallest gap between consecutive sample times (from t = 0), or t_end."""
    times = np.union1d([0.0, scene.t_end], scene.samples)
    return float(np.diff(times[times <= scene.t_end]).min())


def run_batch(scenes: Sequence, method: str | None = None, dt: float | None = None,
              progress: Callable | None = None,
              observe: Callable | None = None) -> BatchResult:
    """Integrate every scene's ensemble in one batch (module doc).

    ``progress(t, diameter, extra)`` is called at samples; ``observe(state, live)`` too, with
    the stacked state of the ensembles ``live`` (indices into ``scenes``) before any leaves.
    """
    check_batch(scenes)
    plan_ = batch_plan(scenes[0], method, dt)
    scenes = [prepare(s, plan_) for s in scenes]
    model, grp = scenes[0].model, scenes[0].model.rotations
    b, n, tol = len(scenes), model.n_agents, scenes[0].tolerance
    system = BatchSystem(model, b)
    state = stack_states(grp, [s.initial for s in scenes])
    rec = _Record(scenes[0], b)
    t0 = time.perf_counter()
    live = np.arange(b)
    run = plan_.method.solver(system, state, scenes[0].t_end, scenes[0].samples, plan_.dt)
    observe = observe or (lambda st, live: None)
    observe(state, live)
    live = rec.sample(state, live, tol)
    while len(live) and run.status == RUNNING:
        for st in run.step():
            observe(st, live)
            kept = rec.sample(st, live, tol)
            if progress is not None:
                worst = rec.diameters[-1][live].max()
                progress(st.t, float(worst), f"  {b - len(kept)}/{b} matched")
            if len(kept) < len(live):
                system = BatchSystem(model, len(kept))
                run.system = system
                run.state = take_ensembles(grp, st, np.searchsorted(live, kept), n)
            live = kept
    if len(live):
        rec.finish(system, run.state, live)
    return rec.result(plan_, run.nsteps, run.nfev, time.perf_counter() - t0)


class _Record:
    """Diameters at samples; the final state of each ensemble as it matches or at t_end."""

    def __init__(self, scene: Scene, b: int) -> None:
        m = scene.model
        self.grp, self.n, self.d, self.b = m.rotations, m.n_agents, m.dim, b
        self.times: list[float] = []
        self.diameters: list[np.ndarray] = []
        self.converged_at = np.full(b, np.nan)
        self.final_t = np.full(b, np.nan)
        self.final_x = np.zeros((b, self.n, self.d))
        self.final_rot = np.zeros((b, self.n, self.d, self.d))
        self.final_matching = np.full(b, np.nan)
        self.measures = np.full((3, b), np.nan)
        self.initial_rotation: np.ndarray | None = None
        self.kappa_rate = m.kappa / (m.gamma if m.gamma > 0 else 1.0)
        self.model = m

    def keep(self, state: State, picked: np.ndarray, rows_of_live: np.ndarray,
             matching: np.ndarray) -> None:
        gs = state.all_groups()[0]
        rows = ensemble_rows(rows_of_live, self.n)
        self.final_t[picked] = state.t
        self.final_x[picked] = gs.x[rows].reshape(-1, self.n, self.d)
        mats = self.grp.to_matrices(self.grp.take(gs.rot, rows))
        self.final_rot[picked] = mats.reshape(-1, self.n, self.d, self.d)
        self.final_matching[picked] = matching

    def sample(self, state: State, live: np.ndarray, tol: float) -> np.ndarray:
        """Record a sample of the live ensembles; return those that have not matched."""
        met = batch_metrics(self.model, state, matching_only=self.initial_rotation is not None)
        row = np.full(self.b, np.nan)
        row[live] = met.matching
        self.times.append(state.t)
        self.diameters.append(row)
        if self.initial_rotation is None:
            assert met.rotation is not None, "the first sample has every diameter"
            self.initial_rotation = met.rotation.copy()
        done = met.matching < tol
        self.converged_at[live[done]] = state.t
        self.keep(state, live[done], np.flatnonzero(done), met.matching[done])
        return live[~done]

    def finish(self, system: BatchSystem, state: State, live: np.ndarray) -> None:
        met = batch_metrics(self.model, state)
        self.keep(state, live, np.arange(len(live)), met.matching)
        eq = equilibrium_measures(system, state)
        self.measures[:, live] = [eq.stationarity, eq.order_parameter, eq.asymmetry]

    def result(self, plan_: Plan, steps: int, nfev: int, wall: float) -> BatchResult:
        still, order, asym = self.measures
        assert self.initial_rotation is not None and plan_.dt is not None, "sampled, fixed step"
        return BatchResult(np.array(self.times), np.array(self.diameters), self.initial_rotation,
                           self.converged_at, self.final_t, self.final_x, self.final_rot,
                           self.final_matching, still, order, asym,
                           classify(self.converged_at, still, order, asym, self.kappa_rate),
                           plan_.name, plan_.dt, steps, nfev, wall)


def classify(converged_at: np.ndarray, stationarity: np.ndarray, order_parameter: np.ndarray,
             asymmetry: np.ndarray, rate: float = 1.0) -> np.ndarray:
    """OUTCOMES label per ensemble from its end-state measures (module doc)."""
    out = np.full(len(converged_at), "too slow", dtype=object)
    still = stationarity < STILL * rate
    out[still] = "other equilibrium"
    out[still & (order_parameter < NO_MEAN_FIELD)] = "twisted"
    out[still & (order_parameter >= NO_MEAN_FIELD) & (asymmetry < SYMMETRIC)] = "antipodal"
    out[~np.isnan(converged_at)] = "matched"
    return out.astype(str)
