"""One solver harness for the accuracy benchmarks (a helper, not a family).

``solve(scene, solver, times)`` runs a registered fixed-step integrator, ours adaptive or
scipy's ``solve_ivp`` (on the flattened system of ``benchmarks/core_families/paper_rhs.py``) on a
single-group
congruent scene and returns the sample times, absolute centroids, rotation matrices, W
(second order), the right-hand-side evaluations, steps and the wall time of the call.
``measure`` runs a list of solvers round-robin (a burst of machine load hits every solver
alike); a refusal (``StabilityError``) or a failure is a result, not a crash.
"""

import time
from dataclasses import dataclass, field

import numpy as np

SCIPY_METHODS = ("RK45", "DOP853")


@dataclass(frozen=True)
class Solution:
    """Arrays over the output times: centroids (T, N, d), mats (T, N, d, d),
    w (T, N, d, d) or None."""

    times: np.ndarray
    centroids: np.ndarray
    mats: np.ndarray
    w: object
    evals: int
    steps: object
    wall: float


@dataclass
class Solver:
    """One solver at one setting (kind: fixed | adaptive | scipy) and what its runs gave."""

    name: str
    kind: str
    value: float
    status: str = "ok"
    walls: list = field(default_factory=list)
    out: Solution = None
    err: float = None  # scores a family gives the first run
    orth: float = None

    @property
    def param(self):
        return f"h = {self.value:g}" if self.kind == "fixed" else f"tol = {self.value:.0e}"

    @property
    def ok(self):
        return self.status == "ok"

    @property
    def timing(self):
        from ..timing import Timing

        return Timing(tuple(self.walls))

    @property
    def best(self):
        return self.timing.best

    @property
    def median(self):
        return self.timing.median


def solvers_for(order, steps, tolerances, scipy=SCIPY_METHODS):
    """Every registered integrator accepting the model at each step; ours adaptive and scipy's
    at each tolerance."""
    from polymatch_ros.core import METHODS

    out = [
        Solver(name, "fixed", h)
        for name, meth in METHODS.items()
        if order in meth.info.models
        for h in steps
    ]
    out += [Solver("adaptive (ours)", "adaptive", tol) for tol in tolerances]
    return out + [Solver(name, "scipy", tol) for name in scipy for tol in tolerances]


def state_arrays(scene, states):
    """(centroids, matrices, W skew or None) of single-group states, absolute coordinates."""
    grp = scene.model.rotations
    cents = np.array([st.groups[0].x + scene.origin for st in states])
    mats = np.array([grp.to_matrices(st.groups[0].rot) for st in states])
    w = None
    if scene.model.order == 2:
        w = np.array([grp.algebra_to_skew(st.groups[0].w) for st in states])
    return cents, mats, w


def solve(scene, solver, times, flat=None):
    """Run ``solver`` on ``scene`` to ``times`` (scipy: ``None`` = its own accepted steps)."""
    if solver.kind == "scipy":
        from scipy.integrate import solve_ivp

        from .paper_rhs import FlatSystem

        flat = flat or FlatSystem.for_scene(scene)
        y0 = flat.initial(scene)
        t0 = time.perf_counter()
        sol = solve_ivp(
            flat.rhs,
            (0.0, scene.t_end),
            y0,
            method=solver.name,
            rtol=solver.value,
            atol=solver.value,
            t_eval=times,
        )
        wall = time.perf_counter() - t0
        if not sol.success:
            raise RuntimeError(
                f"scipy {solver.name} failed at tol {solver.value:g}: {sol.message}"
            )
        u = flat.unpack(sol.y)
        return Solution(sol.t, u["x"], u["rot"], u.get("w"), int(sol.nfev), len(sol.t) - 1, wall)
    from polymatch_ros.core import simulate

    if solver.kind == "fixed":
        kw = {"method": solver.name, "dt": solver.value}
    else:
        kw = {"method": "adaptive", "tolerance": solver.value}
    t0 = time.perf_counter()
    traj = simulate(scene, samples=times, metrics=False, keep_states=True, **kw)
    wall = time.perf_counter() - t0
    cents, mats, w = state_arrays(traj.scene, traj.states)
    return Solution(
        np.array(traj.times, dtype=float), cents, mats, w, int(traj.rhs_evals), traj.steps, wall
    )


def refusal_status(exc):
    """'refused (unstable): dt < ...' from a StabilityError's ``limit`` field."""
    limit = getattr(exc, "limit", None)
    return "refused (unstable)" + (f": dt < {limit:.3g}" if limit else "")


def measure(solvers, scene, times, repeats, log, warmup=False):
    """Run every live solver ``repeats`` times round-robin; ``solver.out`` keeps the first run."""
    from polymatch_ros.core import StabilityError

    from .paper_rhs import FlatSystem

    flat = FlatSystem.for_scene(scene)
    if warmup:  # untimed, each solver once at its first setting: imports, caches, first calls
        for solver in {s.name: s for s in reversed(solvers)}.values():
            try:
                solve(scene, solver, times, flat)
            except Exception:  # the timed rounds record what goes wrong
                pass
    for r in range(repeats):
        live = [s for s in solvers if s.ok]
        log(f"{scene.name}: round {r + 1}/{repeats}: {len(live)} runs")
        for solver in live:
            try:
                out = solve(scene, solver, times, flat)
            except StabilityError as exc:
                solver.status = refusal_status(exc)
                continue
            except Exception as exc:  # a solver that fails is a result, not a crash
                solver.status = f"failed: {str(exc).splitlines()[0][:60]}"
                continue
            solver.walls.append(out.wall)
            if solver.out is None:
                solver.out = out
    return flat
