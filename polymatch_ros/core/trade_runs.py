"""One timed run of one setting of the trade (``core.trade``): its vertices at the sample times.

Our integrators run the centralised simulator's own loop (``simulate.choose_numerics``,
``prepare``, the method's ``solver``), timed around the stepping alone, with the deadline
checked after every step; scipy's DOP853 integrates the flattened model (``core.stepping.flat``)
with the deadline checked at every evaluation.  A run past the deadline raises ``OverBudget``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from .errors import PolymatchError
from .metrics import vertices
from .model import State, System
from .stepping.flat import FlatModel
from .stepping.simulate import choose_numerics, prepare
from .stepping.solver import RUNNING

if TYPE_CHECKING:
    from .scenes.scene import Scene

__all__ = ["OverBudget", "Output", "Runs", "SCIPY_NAME", "max_vertex_error"]

SCIPY_NAME = "scipy DOP853"


class OverBudget(PolymatchError):
    """A run passed the deadline: it is stopped (and the grid with it)."""


@dataclass(frozen=True)
class Output:
    """A run's vertices per group, (samples, N, vertices, d), with its cost: its wall time and
    the CPU time of the thread that ran it (``cpu``: what the run costs whatever else the
    machine runs; the budget's predictions are priced by it)."""

    verts: list[np.ndarray]
    wall: float
    evals: int
    steps: int | None    # accepted steps (None: scipy's solve_ivp does not say)
    cpu: float = 0.0


def max_vertex_error(a: list[np.ndarray], b: list[np.ndarray]) -> float:
    """max over samples, groups, agents and vertices of the Euclidean distance |a - b|."""
    return max(float(np.sqrt(np.max(np.sum((x - y) ** 2, axis=-1)))) for x, y in zip(a, b))


class Runs:
    """Runs of one scene on one grid of sample times, before one deadline (perf_counter s).

    ``distributed``: fixed steps run the model as the lockstep agents do (on a graph the
    centroids integrated with the stages, ``simulate.prepare``).
    """

    def __init__(self, scene: Scene, times: np.ndarray, deadline: float,
                 distributed: bool = False) -> None:
        self.scene, self.times, self.deadline = scene, times, deadline
        self.distributed = distributed
        self.flat: FlatModel | None = None

    def ours(self, method: str, dt: float | None, tol: float | None) -> Output:
        """A registered method at dt, or the adaptive one at tol (StabilityError: refused)."""
        p = choose_numerics(self.scene, method, dt, tol)
        scene = prepare(self.scene, p, distributed=self.distributed and dt is not None)
        state = State(0.0, tuple(replace(gs) for gs in scene.initial.all_groups()))
        states = [state]
        clock, deadline = time.perf_counter, self.deadline
        start, cpu = clock(), time.thread_time()
        run = p.method.solver(System(scene.model), state, scene.t_end, self.times, p.dt)
        while run.status == RUNNING:
            states.extend(run.step())
            if clock() > deadline:
                raise OverBudget(f"{p.name} passed the deadline at t = {run.state.t:g}")
        wall, cpu = clock() - start, time.thread_time() - cpu
        got = np.array([st.t for st in states])
        if len(got) != len(self.times) or np.max(np.abs(got - self.times)) > 1e-9 * max(
                1.0, scene.t_end):
            raise PolymatchError(f"{p.name}: its sample times are not the grid's")
        return Output(self._state_vertices(scene, states), wall, run.nfev, run.nsteps, cpu)

    def _state_vertices(self, scene: Scene, states: list[State]) -> list[np.ndarray]:
        model = scene.model
        out = []
        for gi, g in enumerate(model.groups):
            rows = [st.groups[gi] for st in states]
            x = np.array([gs.x for gs in rows if gs is not None])
            mats = np.array([model.rotations.to_matrices(gs.rot) for gs in rows
                             if gs is not None])
            out.append(vertices(x, mats, g.reference, g.scales))
        return out

    def scipy(self, tol: float) -> Output:
        """scipy's DOP853 at rtol = atol = tol on the flattened model (``core.stepping.flat``)."""
        from scipy.integrate import solve_ivp

        if self.flat is None:
            self.flat = FlatModel(self.scene)
        flat, clock, deadline = self.flat, time.perf_counter, self.deadline

        def rhs(t: float, y: np.ndarray) -> np.ndarray:
            if clock() > deadline:
                raise OverBudget(f"{SCIPY_NAME} passed the deadline at t = {t:g}")
            return flat.rhs(t, y)

        y0 = flat.initial(self.scene)
        start, cpu = clock(), time.thread_time()
        sol = solve_ivp(rhs, (0.0, self.scene.t_end), y0, method="DOP853", rtol=tol,
                        atol=tol, t_eval=self.times)
        wall, cpu = clock() - start, time.thread_time() - cpu
        if not sol.success:
            raise PolymatchError(f"{SCIPY_NAME}: {sol.message}")
        out = []
        for gi, g in enumerate(self.scene.model.groups):
            parts = [flat.unpack(col)[gi] for col in sol.y.T]
            x = np.array([p["x"] for p in parts])
            mats = np.array([p["rot"] for p in parts])
            out.append(vertices(x, mats, g.reference, g.scales))
        return Output(out, wall, int(sol.nfev), None, cpu)

