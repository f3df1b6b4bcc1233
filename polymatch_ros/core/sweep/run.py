"""Sweeps: many independent ensembles of one scene kind, integrated together (``sweep.batch``).

``run_batch(scenes)`` integrates B single-group scenes that differ only in their initial
states with the scene's fixed-step integrator (or another registered one, or rkmk8 of
``chart_rk``, by default at the sample interval), all B along one batch axis, and records
per ensemble what ``simulate(scene, stop_when_converged=True)`` would: the first sample
time at which the matching diameter is below the scene's tolerance (Theorems 4.1/4.2),
the state there (or at t_end), and the diameters at every sample.  Ensembles that have
matched leave the batch (their rows are dropped), so the batch shrinks as it converges.

Ensembles that do not match by t_end are classified from the metrics of their end state
(``classify``): an equilibrium that is not consensus (the rotation field max_i |W_i| is
~0, ``metrics.stationarity``, and the rotations are not all within NEAR_CONSENSUS of each
other) is *antipodal* when every pair O_i^T O_j is symmetric (each pair at consensus or a
half-turn apart) with a non-zero mean field, *twisted* when the mean field S = sum_k O_k
vanishes (splay/twisted states, where the torque is zero because S is) or, on a ring, when
every step O_j^T O_{j+1} around the ring turns by the same angle (``rings``: its winding
number q in d = 2, its total turn and loop class in every d); any other equilibrium is
*other equilibrium*; anything still moving, or still converging to consensus, is *too
slow* (t_end too short for it).

On a communication graph (the scene's ``graph`` key, ``core.graph``) every ensemble keeps
its own graph (``graphs.BatchGraphs``); stillness is measured against kappa/gamma times
the largest graph's Laplacian spectral radius (1 on the complete graph).  With
``settle=True`` an ensemble that is still at a sample, and not near consensus, leaves
the batch there, classified as at t_end (the equilibria of sparse graphs are reached long
before a generous t_end).
"""

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import ParameterError
from ..model import State
from ..scenes.scene import Scene
from ..so.base import Array, RotationGroup
from ..stepping.integrators import check_stability
from ..stepping.simulate import NumericalPlan, choose_numerics, prepare
from ..stepping.solver import RUNNING
from . import chart_rk
from .batch import (
    BatchSystem,
    batch_metrics,
    ensemble_rows,
    equilibrium_measures,
    pair_diameters,
    stack_states,
    stationarity,
    take_ensembles,
)
from .graphs import BatchGraphs
from .rings import HALF_TURN_MARGIN, RingMeasures, ring_measures

OUTCOMES = ("matched", "antipodal", "twisted", "other equilibrium", "too slow")
#: an end state is an equilibrium when max_i |W_i| < STILL * kappa / gamma
STILL = 1e-6
#: |mean O| / sqrt(d) below this: the mean field vanishes (a twisted/splay state)
NO_MEAN_FIELD = 1e-3
#: max_{i,j} |O_i^T O_j - O_j^T O_i| below this: every pair at consensus or a half-turn apart
SYMMETRIC = 1e-3
#: a still end state whose rotation diameter max |O_i - O_j|_F is below this is converging
#: to consensus (slowly: sparse graphs), not an equilibrium of its own
NEAR_CONSENSUS = 1e-2
#: on a ring, steps O_j^T O_{j+1} whose angles differ by less than this (rad) are uniform
UNIFORM_TWIST = 1e-3
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
    graph: str                     # the graph's kind ("complete", "ring", ...)
    ring: RingMeasures | None      # on a ring: winding number, turn, loop class per ensemble
    method: str
    dt: float
    steps: int
    rhs_evals: int                 # of the batch (each evaluation serves every live ensemble)
    wall_time: float
    final_rotation: np.ndarray | None = None   # rotation diameter at final_t (nan: matched)


def check_batch(scenes: Sequence) -> None:
    """Refuse scenes that cannot share one batch (ParameterError: exit 2)."""
    if not scenes:
        raise ParameterError("a sweep needs at least one ensemble")
    first = scenes[0]
    m0 = first.model
    if len(m0.groups) != 1 or m0.groups[0].scales is not None:
        raise ParameterError(f"{first.name}: a sweep takes scenes with one congruent group")
    key = _batch_key(first)
    for s in scenes[1:]:
        if _batch_key(s) != key or \
                not np.array_equal(s.model.groups[0].reference, m0.groups[0].reference):
            raise ParameterError(f"{s.name}: ensembles of one batch must share the model, "
                                 "shape, graph kind, integrator and times")


def _batch_key(s: Scene) -> tuple:
    m, g = s.model, s.model.groups[0].graph
    graph = None if g is None else (g.kind, g.directed, g.normalise)
    return (m.dim, m.order, m.kappa, m.gamma, m.mass, m.n_agents, s.t_end, s.tolerance,
            s.integrator, m.rotations.name, m.centroids, graph)


def batch_graphs(scenes: Sequence) -> BatchGraphs | None:
    """Every ensemble's graph (None on the complete graph)."""
    if scenes[0].model.groups[0].graph is None:
        return None
    return BatchGraphs.of([s.model.groups[0].graph for s in scenes])


def batch_plan(scene: Scene, method: str | None = None, dt: float | None = None) -> NumericalPlan:
    """The batch's fixed-step integrator: ``simulate.choose_numerics``'s, or one of BATCH_METHODS.

    A BATCH_METHODS method steps by the scene's smallest sample interval unless ``dt`` is
    given (its steps end on the samples, where ensembles are tested and leave).  ``scene``
    is the stiffest ensemble's (its graph's Laplacian has the largest spectral radius).
    """
    if method not in BATCH_METHODS:
        numerics = choose_numerics(scene, method, dt)
        if numerics.dt is None:
            raise ParameterError("a sweep takes fixed-step integrators (the adaptive one would "
                                 "share one step size between independent ensembles)")
        return numerics
    step = dt if dt is not None else sample_interval(scene)
    if not (step > 0 and math.isfinite(step)):
        raise ParameterError(f"dt must be a positive number, got {step}")
    step = min(step, scene.t_end)
    meth = getattr(chart_rk, BATCH_METHODS[method])
    check_stability(meth, scene.model, step)
    return NumericalPlan(meth, step, None, "chosen explicitly")


def sample_interval(scene: Scene) -> float:
    """The smallest gap between consecutive sample times (from t = 0), or t_end."""
    times = np.union1d([0.0, scene.t_end], scene.samples)
    return float(np.diff(times[times <= scene.t_end]).min())


def run_batch(scenes: Sequence, method: str | None = None, dt: float | None = None,
              progress: Callable | None = None,
              observe: Callable | None = None, settle: bool = False) -> BatchResult:
    """Integrate every scene's ensemble in one batch (module doc).

    ``progress(t, diameter, extra)`` is called at samples; ``observe(state, live)`` too, with
    the stacked state of the ensembles ``live`` (indices into ``scenes``) before any leaves.
    ``settle``: ensembles at an equilibrium other than consensus leave at a sample.
    """
    check_batch(scenes)
    graphs = batch_graphs(scenes)
    numerics = batch_plan(scenes[0 if graphs is None else graphs.stiffest()], method, dt)
    scenes = [prepare(s, numerics) for s in scenes]
    model, grp = scenes[0].model, scenes[0].model.rotations
    b, n, tol = len(scenes), model.n_agents, scenes[0].tolerance
    system = BatchSystem(model, b, graphs)
    state = stack_states(grp, [s.initial for s in scenes])
    rec = _Record(scenes[0], b, graphs)
    t0 = time.perf_counter()
    live = np.arange(b)
    run = numerics.method.solver(system, state, scenes[0].t_end, scenes[0].samples, numerics.dt)
    observe = observe or (lambda st, live: None)
    observe(state, live)
    live = rec.sample(state, live, tol)
    while len(live) and run.status == RUNNING:
        for st in run.step():
            observe(st, live)
            kept = rec.sample(st, live, tol)
            if settle and len(kept):
                kept = rec.settle(system, st, live, kept)
            if progress is not None:
                worst = rec.diameters[-1][live].max()
                progress(st.t, float(worst), f"  {b - len(kept)}/{b} done")
            if 0 < len(kept) < len(live):
                system = BatchSystem(model, len(kept), rec.graphs_of(kept))
                run.system = system
                run.state = take_ensembles(grp, st, np.searchsorted(live, kept), n)
            live = kept
    if len(live):
        rec.finish(system, run.state, live)
    return rec.result(numerics, run.nsteps, run.nfev, time.perf_counter() - t0)


class _Record:
    """Diameters at samples; the final state of each ensemble as it matches or at t_end."""

    def __init__(self, scene: Scene, b: int, graphs: BatchGraphs | None) -> None:
        m = scene.model
        self.grp, self.n, self.d, self.b = m.rotations, m.n_agents, m.dim, b
        self.graphs = graphs
        self.times: list[float] = []
        self.diameters: list[np.ndarray] = []
        self.converged_at = np.full(b, np.nan)
        self.final_t = np.full(b, np.nan)
        self.final_x = np.zeros((b, self.n, self.d))
        self.final_rot = np.zeros((b, self.n, self.d, self.d))
        self.final_matching = np.full(b, np.nan)
        self.measures = np.full((4, b), np.nan)
        self.initial_rotation: np.ndarray | None = None
        stiffness = 1.0 if graphs is None else max(g.coupling_rate() for g in graphs.graphs)
        self.kappa_rate = stiffness * m.kappa / (m.gamma if m.gamma > 0 else 1.0)
        self.model = m

    def graphs_of(self, ensembles: np.ndarray) -> BatchGraphs | None:
        return None if self.graphs is None else self.graphs.take(ensembles)

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

    def settle(self, system: BatchSystem, state: State, live: np.ndarray,
               kept: np.ndarray) -> np.ndarray:
        """Of ``kept`` (not matched), those not yet still away from consensus (``settle``)."""
        pos = np.searchsorted(live, kept)
        still = stationarity(system, state)[pos] < STILL * self.kappa_rate
        if not still.any():
            return kept
        sub = take_ensembles(system.group, state, pos[still], self.n)
        gs = sub.all_groups()[0]
        entries = ensembles_entries(system.group, gs.rot, self.n)
        settled = kept[still][pair_diameters(entries) >= NEAR_CONSENSUS]
        if len(settled):
            where = np.searchsorted(live, settled)
            sub = take_ensembles(system.group, state, where, self.n)
            self.finish(BatchSystem(self.model, len(settled), self.graphs_of(settled)), sub,
                        settled)
        return np.setdiff1d(kept, settled)

    def finish(self, system: BatchSystem, state: State, live: np.ndarray) -> None:
        met = batch_metrics(self.model, state)
        self.keep(state, live, np.arange(len(live)), met.matching)
        eq = equilibrium_measures(system, state)
        self.measures[:, live] = [eq.stationarity, eq.order_parameter, eq.asymmetry,
                                  met.rotation]

    def result(self, numerics: NumericalPlan, steps: int, nfev: int, wall: float) -> BatchResult:
        still, order, asym, rotation = self.measures
        assert self.initial_rotation is not None and numerics.dt is not None, "sampled, fixed step"
        kind = "complete" if self.graphs is None else self.graphs.graphs[0].kind
        ring = ring_measures(self.final_rot) if kind == "ring" else None
        twisted = None if ring is None else ring_twisted(ring)
        return BatchResult(np.array(self.times), np.array(self.diameters), self.initial_rotation,
                           self.converged_at, self.final_t, self.final_x, self.final_rot,
                           self.final_matching, still, order, asym,
                           classify(self.converged_at, still, order, asym, self.kappa_rate,
                                    rotation, twisted),
                           kind, ring, numerics.name, numerics.dt, steps, nfev, wall, rotation)


def ensembles_entries(grp: RotationGroup, rot: Array, n: int) -> np.ndarray:
    """Rotation entries laid out (d d, N, B) for ``pair_diameters`` (rotation diameters)."""
    from .batch import batch_rotations, ensembles_last
    return ensembles_last(batch_rotations(grp).flat(rot).T, n)


def ring_twisted(ring: RingMeasures) -> np.ndarray:
    """Ring end states whose steps all turn by one angle, below a half-turn, >= 1/2 turn in all."""
    return ((ring.step_spread < UNIFORM_TWIST) & (ring.step_max < np.pi - HALF_TURN_MARGIN)
            & (ring.turn >= 0.5))


def classify(converged_at: np.ndarray, stationarity: np.ndarray, order_parameter: np.ndarray,
             asymmetry: np.ndarray, rate: float = 1.0, rotation: np.ndarray | None = None,
             twisted_ring: np.ndarray | None = None) -> np.ndarray:
    """OUTCOMES label per ensemble from its end-state measures (module doc)."""
    out = np.full(len(converged_at), "too slow", dtype=object)
    still = stationarity < STILL * rate
    if rotation is not None:
        still &= ~(rotation < NEAR_CONSENSUS)
    out[still] = "other equilibrium"
    out[still & (order_parameter >= NO_MEAN_FIELD) & (asymmetry < SYMMETRIC)] = "antipodal"
    twisted = order_parameter < NO_MEAN_FIELD
    if twisted_ring is not None:
        twisted |= twisted_ring
    out[still & twisted] = "twisted"
    out[~np.isnan(converged_at)] = "matched"
    return out.astype(str)
