"""The one solver contract, after scipy.integrate's OdeSolver: the base owns the bookkeeping.

A *method* (``Method``) says how one step is made of stages; it is stateless and
shared (the registry ``integrators.METHODS``).  ``Method.step(system, y, h)`` is
a generator: each stage yields a ``Request`` (the stage whose mean field of
(A-1)/(A-2) is needed), is sent back the ensemble's arrays and finally returns
the new state.  The base class does what every method shares: the first
evaluation at the step start, the exact centroid flow of Proposition 2.1 when
centroids decouple, and the end-of-step state; a subclass supplies only its
stages (``Method.stages``).

A *run* (``FixedStepSolver`` here, ``adaptive.AdaptiveSolver``) advances one
state to ``t_end``: ``step()`` takes one step and returns the states it reached
at sample times, ``status`` says whether it is running, and ``nsteps``/``nfev``
count steps and right-hand-side evaluations.  The centralised simulator has one
loop over any run; ``drive`` is the one driver of a step, used by the runs and
by both ROS agent modes.
"""

import math
from collections.abc import Callable, Generator, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..model import Coupling, GroupState, Request, State, System
from ..so.base import RECYCLED_MIN_BYTES, recycled, row_blocks, scratch

RUNNING, FINISHED = "running", "finished"

#: a stage's answer: per group an object with .x, .rot (and .v), in agent-index order
Ensemble = Sequence[Any]
Stepper = Generator[Request, Ensemble, State]
#: step-grid points closer than this (relative to dt) to t_end are t_end itself
GRID_RTOL = 1e-9


@dataclass(frozen=True)
class MethodInfo:
    """What ``polymatch integrators`` lists about a method."""

    name: str
    order: int
    stages: int           # right-hand-side evaluations per step
    rounds: int           # exchange rounds per step in lockstep (FSAL methods: fewer than stages)
    family: str
    models: tuple         # model orders the method accepts
    summary: str


def drive(method: "Method", system: System, state: State, h: float,
          answer: Callable[[Request, int], Ensemble] | None = None) -> State:
    """Advance ``state`` by one step ``h`` of ``method``: the one driver of every stepper.

    A method's step is a generator: each stage yields a request (what the mean field of
    (A-1)/(A-2) needs from the ensemble at that stage) and is sent back the ensemble's
    arrays; it returns the new state.  ``answer(request, stage_index)`` supplies those
    arrays: the centralised simulator answers from the request's own arrays (the default),
    a lockstep agent with its peers' messages of that round, a realtime agent with the
    newest poses it has heard.
    """
    gen = method.step(system, state, h)
    stage = 0
    try:
        request = next(gen)
        while True:
            groups = request.stage.groups if answer is None else answer(request, stage)
            stage += 1
            request = gen.send(groups)
    except StopIteration as stop:
        return stop.value


def step_grid(t_end: float, dt: float) -> np.ndarray:
    """Step end times k*dt (k = 1..n), the last one clipped to t_end."""
    n = max(1, int(math.ceil(t_end / dt - GRID_RTOL)))
    grid = dt * np.arange(1, n + 1)
    grid[-1] = t_end
    return grid


class Method:
    """A fixed-step method: ``step`` is the shared template, ``stages`` the method's own part."""

    info: MethodInfo

    @property
    def name(self) -> str:
        return self.info.name

    def step(self, system: System, y: State, h: float) -> Stepper:
        """One step of h from y (generator, see the module docstring).

        Evaluates the mean field at y (or reuses the one cached there: FSAL), advances
        decoupled centroids by their exact flow (Proposition 2.1), runs the method's
        stages and returns the state at y.t + h with those centroids.
        """
        self.check_system(system)
        coupling = yield from system.evaluate(y, first_stage=True)
        centroids = exact_centroids(system, y, coupling, h) if system.model.centroids_exact \
            else None
        end = yield from self.stages(system, y, h, coupling, centroids)
        return finish(y, end, h, centroids)

    def check_system(self, system: System) -> None:
        """Refuse a system the method cannot integrate (called before the first stage)."""

    def stages(self, system: System, y: State, h: float, coupling: Coupling,
               centroids: list | None) -> Stepper:
        """Generator: the method's stages after the first evaluation; returns the end state.

        ``coupling`` is the mean field at y, ``centroids`` the exact (x, v) per group at
        y.t + h (None when the stages integrate the centroids).  The returned state's
        centroids are replaced by ``centroids``; its ``coupling`` is kept (FSAL).
        """
        raise NotImplementedError

    def spectral_radius(self, h: float, a: np.ndarray) -> float:
        """Spectral radius of the step's amplification on the linear test system y' = a y."""
        raise NotImplementedError

    def solver(self, system: System, state: State, t_end: float,
               samples: Sequence[float] | np.ndarray,
               dt: float | None = None) -> "FixedStepSolver":
        """A run of this method from ``state`` to ``t_end`` with steps of ``dt``."""
        if dt is None:
            raise TypeError(f"{self.name}: a fixed-step run needs a step dt")
        return FixedStepSolver(self, system, state, t_end, samples, dt)


def lincomb(base: Any, h: float, coefs: Sequence[float], terms: Sequence) -> Any:
    """base + h * sum coefs[j] * terms[j] (skipping zero coefficients); base may be None (zero).

    Large float arrays of one shape are summed block of rows by block (``row_blocks``) into one
    result array (``recycled``; ``base`` is never modified): the operations and their order
    are those of out + (h c) t term by term, without a fresh array per term.
    """
    scaled = [(h * c, t) for c, t in zip(coefs, terms) if c != 0.0 and t is not None]
    if scaled and getattr(scaled[0][1], "nbytes", 0) >= RECYCLED_MIN_BYTES \
            and all(_same_floats(base, t, scaled[0][1].shape) for _, t in scaled):
        return _row_block_sum(base, scaled)
    out = base              # small arrays: the same operations in the same order, term by term
    for hc, t in scaled:
        out = hc * t if out is None else out + hc * t
    return out


def _same_floats(base: Any, term: Any, shape: tuple) -> bool:
    """True when term is a float array of ``shape`` (rows first) and base None or one too."""
    return len(shape) > 0 and all(
        a is None or (isinstance(a, np.ndarray) and a.dtype == np.float64 and a.shape == shape)
        for a in (base, term))


def _row_block_sum(base: np.ndarray | None, scaled: list) -> np.ndarray:
    """base + sum hc t over [(hc, t)] (base None: zero), one block of rows at a time."""
    shape = scaled[0][1].shape
    out = recycled(shape)
    rows, blocks = row_blocks(shape)
    temp = scratch("lincomb", (rows,) + shape[1:])
    for block in blocks:
        acc, term = out[block], temp[:block.stop - block.start]
        (hc, t), rest = scaled[0], scaled[1:]
        if base is None:
            np.multiply(t[block], hc, out=acc)
        else:
            np.add(base[block], np.multiply(t[block], hc, out=term), out=acc)
        for hc, t in rest:
            acc += np.multiply(t[block], hc, out=term)
    return out


def exact_centroids(system: System, y: State, coupling: Coupling, h: float) -> list:
    """Proposition 2.1 flow of every local group's centroids over h (from the stage-1 mean field).

    Inactive groups (no local rows) are None.
    """
    return system.per_active_group(
        y.groups, lambda gi, gs: system.exact_centroids(gi, gs, coupling, h))


def advance_active(system: System, groups: Sequence[GroupState | None],
                   fn: Callable[[int, GroupState], Any]) -> tuple[tuple, list]:
    """(new group states, per-group extras) from fn(gi, gs) -> (new state, extra).

    A group without local rows (``System.is_active``) is kept as it is, its extra None.
    """
    done = system.per_active_group(groups, fn)
    states = tuple(gs if r is None else r[0] for gs, r in zip(groups, done))
    return states, [None if r is None else r[1] for r in done]


def with_centroids(groups: Sequence, centroids: list | None) -> tuple:
    """The groups with (x, v) replaced where ``centroids`` has an entry."""
    if centroids is None:
        return tuple(groups)
    return tuple(gs if c is None else GroupState(c[0], gs.rot, c[1], gs.w)
                 for gs, c in zip(groups, centroids))


def finish(y: State, end: State, h: float, centroids: list | None) -> State:
    """The state at y.t + h: the stages' end with the exact centroids, its coupling kept."""
    return State(y.t + h, with_centroids(end.groups, centroids), coupling=end.coupling)


class FixedStepSolver:
    """A run of a fixed-step method on the grid k*dt (the last step clipped to t_end).

    Samples are rounded to the nearest step end; the last step is always a sample.
    """

    def __init__(self, method: Method, system: System, state: State, t_end: float,
                 samples: Sequence[float] | np.ndarray, dt: float) -> None:
        self.method, self.system, self.state = method, system, state
        self.grid = step_grid(t_end, dt)
        times = np.asarray(samples, dtype=float)
        self.sample_steps = set(int(k) for k in np.searchsorted(self.grid,
                                                                 times[times > 0] - 0.5 * dt))
        self.nsteps = 0
        self.nfev = 0
        self.status = RUNNING

    def step(self) -> list[State]:
        """Take one step; return [its end state] when that is a sample, else []."""
        k = self.nsteps
        t_next = self.grid[k]
        self.state = drive(self.method, self.system, self.state, t_next - self.state.t)
        self.state.t = t_next
        self.nsteps += 1
        self.nfev += self.method.info.stages
        last = k == len(self.grid) - 1
        if last:
            self.status = FINISHED
        return [self.state] if k in self.sample_steps or last else []
