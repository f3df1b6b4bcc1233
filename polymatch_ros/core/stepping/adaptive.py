"""Adaptive step size: scipy's DOP853 as a Munthe-Kaas method on SO(d), with dense output.

Each step is taken in psi-coordinates (Cayley, or angles in 2-D) centred at the
current state, so the chart is re-centred every step and rotations stay in
SO(d) to round-off.  In the chart the increment obeys the exact ODE
Theta' = dpsi^{-1}_Theta(W(psi(Theta) O_n)), so DOP853's 8th order, its
embedded 5th/3rd-order error estimate and its 7th-order continuous extension
carry over unchanged: sample times are interpolated inside a step (three extra
evaluations for a step that contains samples), never forced onto the step grid.

Coefficients (A, B, E3, E5, A_EXTRA, C_EXTRA, D), error norm and step-size
control are scipy.integrate.DOP853's.  The increment of every group is one flat
vector, so a stage costs one matrix-vector product plus the right-hand side.
Decoupled centroids follow their exact flow (Proposition 2.1): they neither
cost evaluations nor limit the step.  Centralised only: a distributed ensemble
cannot agree on a step size without an extra round per step.

``AdaptiveLie`` is the method (tableau, tolerances, step cap); ``AdaptiveSolver``
is one run with the contract of ``solver.FixedStepSolver``: ``step()``, ``status``,
``nsteps``/``nfev`` (and ``nrejected``).  ``max_steps`` bounds accepted and rejected
steps together.
"""

import math
from collections.abc import Sequence

import numpy as np
from scipy.integrate import DOP853

from ..centroids import CentroidFlow
from ..errors import PolymatchError, StepLimitError
from ..model import GroupState, Model, State, System
from .adaptive_chart import Chart, RotationRates
from .solver import FINISHED, RUNNING, MethodInfo, exact_centroids, with_centroids
from .stability import test_matrices

SAFETY, MIN_FACTOR, MAX_FACTOR = 0.9, 0.2, 10.0
N_STAGES = DOP853.n_stages
#: steps below this (relative to max(1, |t|)) are round-off: the scene is too stiff
STEP_FLOOR = 1e-12
#: a step that ends this close (relative to max(1, |t_end|)) to t_end ends at t_end
END_RTOL = 1e-13
#: the step cap is this fraction of DOP853's linear stability limit
CAP_FRACTION = 0.9
#: the smallest tolerance worth asking for in double precision (scipy's floor for rtol)
TOLERANCE_FLOOR = 100 * np.finfo(float).eps
N_DENSE = N_STAGES + 1 + len(DOP853.C_EXTRA)
#: step caps by test matrices (``AdaptiveLie.step_cap``)
_CAPS: dict = {}


class AdaptiveLie:
    """DOP853-Lie: the method (scipy's tableau, tolerances, step cap); runs are ``solver``."""

    info = MethodInfo("adaptive", DOP853.order, N_STAGES, 0, "adaptive", (1, 2),
                      "DOP853 (scipy's tableau, step control, dense output) in Cayley/angle "
                      "coordinates, re-centred every step; centralised only")

    def __init__(self, rtol: float, atol: float | None = None,
                 max_steps: int = 10_000_000) -> None:
        self.rtol = float(rtol)
        self.atol = float(rtol if atol is None else atol)
        self.max_steps = int(max_steps)
        self.error_exponent = -1.0 / (DOP853.error_estimator_order + 1)
        self.A, self.B = DOP853.A[:N_STAGES, :N_STAGES], DOP853.B
        self.rows = [np.ascontiguousarray(self.A[s, :s]) for s in range(1, N_STAGES)]
        self.E3, self.E5 = DOP853.E3, DOP853.E5
        # R(z) = 1 + sum_k z^k b^T A^(k-1) 1 (an explicit tableau: a polynomial), highest first
        coefs, vec = [1.0], np.ones(N_STAGES)
        for _ in range(N_STAGES):
            coefs.append(float(self.B @ vec))
            vec = self.A @ vec
        self.stability_poly = np.array(coefs[::-1])
        # the continuous extension: Horner coefficients in the order _dense applies them
        self.dense_extra = list(zip(DOP853.A_EXTRA, DOP853.C_EXTRA))

    @property
    def name(self) -> str:
        return self.info.name

    def step_cap(self, model: Model) -> tuple[float, str]:
        """0.9 x the largest h at which DOP853 is linearly stable on the model's test matrices.

        Near consensus the error estimate lets the step grow until it hovers at the
        stability boundary, which keeps a converged ensemble from staying converged;
        no step beyond the cap can be accurate anyway.  Returns (cap, binding cause).
        The cap depends on the test matrices only: it is computed once per distinct set.
        """
        tests = test_matrices(model)
        key = tuple((np.atleast_2d(mat).tobytes(), np.shape(mat), cause)
                    for _, mat, cause in tests)
        if key not in _CAPS:
            if len(_CAPS) >= 64:
                _CAPS.pop(next(iter(_CAPS)))
            _CAPS[key] = self._bisect_caps(tests)
        return _CAPS[key]

    def _bisect_caps(self, tests: list[tuple[str, np.ndarray, str]]) -> tuple[float, str]:
        best = (np.inf, "")
        for _, mat, cause in tests:
            lam = np.linalg.eigvals(np.atleast_2d(mat))
            rate = float(np.max(np.abs(lam)))
            if rate == 0.0:
                continue
            lo, hi = 0.0, 20.0 / rate
            for _ in range(60):
                mid = 0.5 * (lo + hi)
                if np.all(np.abs(np.polyval(self.stability_poly, mid * lam)) <= 1.0):
                    lo = mid
                else:
                    hi = mid
            if CAP_FRACTION * lo < best[0]:
                best = (CAP_FRACTION * lo, cause)
        return best

    def solver(self, system: System, state: State, t_end: float,
               samples: Sequence[float] | np.ndarray = (),
               dt: float | None = None) -> "AdaptiveSolver":
        """A run from ``state`` to t_end (the latest of t_end and the samples); dt is unused."""
        return AdaptiveSolver(self, system, state, t_end, samples)


class AdaptiveSolver:
    """One adaptive run: ``step()`` takes one accepted step and returns the sample states in it."""

    def __init__(self, method: AdaptiveLie, system: System, state: State, t_end: float,
                 samples: Sequence[float] | np.ndarray = ()) -> None:
        self.method, self.system, self.state = method, system, state
        times = np.union1d(np.asarray(samples, dtype=float), [float(t_end)])
        #: output times still ahead, sorted; ``self.next_sample`` indexes the first one
        self.pending = times[times > state.t]
        self.next_sample = 0
        self.nsteps = self.nfev = self.nrejected = 0
        self.status = RUNNING if len(self.pending) else FINISHED
        if not len(self.pending):
            return
        self.t_end = float(self.pending[-1])
        self.cap = self._check_stiffness()
        self.coupling = system.couple(state.groups)
        self.chart = Chart(system, state)
        #: the one-group, rotations-only evaluation without state objects, where it applies
        self.fast = RotationRates(self.chart) if RotationRates.applies(self.chart) else None
        # stage slopes, reused by every attempt; the last rows hold the dense-output stages
        self.K = np.empty((N_DENSE, self.chart.n))
        self.rotation_scale = np.full(self.chart.n, method.atol + method.rtol * 1.0)
        self.k0 = self.chart.pack(system.rates(state, self.coupling))
        self.nfev += 1
        with np.errstate(over="ignore", invalid="ignore"):
            self.h = min(self._initial_step(self.chart, self.k0, self.t_end - state.t), self.cap)
        if not (math.isfinite(self.h) and self.h > 0):
            self._beyond_precision()

    def _check_stiffness(self):
        """The step cap; refuse before stepping when max_steps cannot reach t_end under it."""
        meth, y = self.method, self.state
        cap, cause = meth.step_cap(self.system.model)
        needed = (self.t_end - y.t) / cap
        if needed > meth.max_steps:
            raise PolymatchError(
                f"adaptive: the scene is stiff ({cause}): an explicit method needs at least "
                f"{needed:.2g} steps to reach t = {self.t_end:g} (max_steps = {meth.max_steps}); "
                "use etd2 for stiff damping, a shorter t_end, or a larger integrator.max_steps")
        return cap

    def _beyond_precision(self):
        raise PolymatchError(
            f"adaptive: tolerance {self.method.rtol:g} is beyond double precision (no step "
            f"meets it at t = {self.state.t:.6g}); use a tolerance of at least "
            f"{TOLERANCE_FLOOR:.1g} or a fixed dt")

    def _count_attempt(self):
        if self.nsteps + self.nrejected >= self.method.max_steps:
            raise StepLimitError(
                f"adaptive: max_steps = {self.method.max_steps} steps (accepted and rejected) "
                f"used up at t = {self.state.t:.6g} of {self.t_end:g}; raise "
                "integrator.max_steps, loosen the tolerance or use a fixed dt")


    def _fun(self, chart, vec, full=False):
        """(flat chart rates, raw rates, stage State) at the increment ``vec``; one evaluation.

        ``full=False``: the flat rates only where ``self.fast`` applies (raw and stage None).
        """
        self.nfev += 1
        fast = self.fast
        if fast is not None:
            k, rot, rate = fast(chart, vec)
            if not full:
                return k, None, None
            stage, raw = fast.stage(chart, rot, rate)
            return k, raw, stage
        stage, thetas = chart.state(vec)
        system = chart.system
        raw = system.rates(stage, system.couple(stage.groups, first_stage=False))
        return chart.pack(system.in_chart(raw, thetas)), raw, stage

    def _error_norm(self, K, h, scale):
        meth = self.method
        err5 = (K.T @ meth.E5) / scale
        err3 = (K.T @ meth.E3) / scale
        n5, n3 = float(err5 @ err5), float(err3 @ err3)
        if n5 == 0.0 and n3 == 0.0:
            return 0.0
        return abs(h) * n5 / math.sqrt((n5 + 0.01 * n3) * len(scale))

    def _attempt(self, chart, h, k0):
        meth, K, fun = self.method, self.K, self._fun
        K[0] = k0
        for s, row in enumerate(meth.rows, start=1):
            K[s] = fun(chart, (row @ K[:s]) * h)[0]
        theta = (K[:N_STAGES].T @ meth.B) * h
        K[N_STAGES], raw_new, y_new = fun(chart, theta, full=True)
        if chart.rotations_only:                     # rotations have unit size: a fixed scale
            scale = self.rotation_scale
        else:
            new_size = np.where(chart.is_rot, 1.0, np.abs(chart.base + theta))
            scale = meth.atol + meth.rtol * np.maximum(chart.base_size, new_size)
        return theta, raw_new, y_new, self._error_norm(K[:N_STAGES + 1], h, scale)

    def _initial_step(self, chart, k0, span):
        scale = self.method.atol + self.method.rtol * chart.base_size
        d0 = float(np.sqrt(np.mean((chart.base_size / scale) ** 2)))
        d1 = float(np.sqrt(np.mean((k0 / scale) ** 2)))
        h0 = 1e-6 if (d0 < 1e-5 or d1 < 1e-5) else 0.01 * d0 / d1
        h0 = min(h0, span)
        k1 = self._fun(chart, h0 * k0)[0]
        d2 = float(np.sqrt(np.mean(((k1 - k0) / scale) ** 2))) / h0
        if max(d1, d2) <= 1e-15:
            h1 = max(1e-6, h0 * 1e-3)
        else:
            h1 = (0.01 / max(d1, d2)) ** (1.0 / (DOP853.order + 1))
        return min(100 * h0, h1, span)

    def _dense(self, h, theta, times):
        """States at ``times`` inside the step (DOP853's continuous extension in the chart).

        The three extra stages fill the last rows of ``self.K``; the polynomial is evaluated
        for all the step's sample times at once, in the same order of operations as scipy's.
        """
        chart, y, K = self.chart, self.state, self.K
        for s, (a, _c) in enumerate(self.method.dense_extra, start=N_STAGES + 1):
            K[s] = self._fun(chart, (K[:s].T @ a[:s]) * h)[0]
        F = np.empty((DOP853.D.shape[0] + 3, chart.n))
        F[0] = theta
        F[1] = h * K[0] - theta
        F[2] = 2 * theta - h * (K[N_STAGES] + K[0])
        F[3:] = h * (DOP853.D @ K)
        x = ((times - y.t) / h)[:, None]
        factors = (x, 1 - x)
        vals = np.zeros((len(times), chart.n))
        for i, f in enumerate(reversed(F)):
            vals += f
            vals *= factors[i % 2]
        return self._sample_states(times.tolist(), vals)

    def _sample_states(self, times, vals):
        """States at ``times`` from their chart coordinates (rows of ``vals``)."""
        chart, y, system = self.chart, self.state, self.system
        if not (chart.single_part and system.model.centroids_exact):
            return [self._with_exact_centroids(chart.state(val)[0], t - y.t, t)
                    for t, val in zip(times, vals)]
        gi, _, shape, _ = chart.parts[0]           # one group, rotations only: no chart states
        gs, grp, groups = y.groups[gi], system.group, list(y.groups)
        assert gs is not None, "the chart's group has rows"
        dts = [t - y.t for t in times]
        all_to_all = isinstance(system.flows[gi], CentroidFlow)
        cents = self._first_order_centroids(gi, gs, dts) if system.model.order == 1 and \
            all_to_all else [system.exact_centroids(gi, gs, self.coupling, dt) for dt in dts]
        rots = grp.retract_each(vals.reshape((len(vals),) + shape), gs.rot)
        out = []
        for t, rot, (x, v) in zip(times, rots, cents):
            groups[gi] = GroupState(x, rot, v, gs.w)
            out.append(State(t, tuple(groups)))
        return out

    def _first_order_centroids(self, gi, gs, dts):
        """``CentroidFlow.advance`` of (A-2)'s all-to-all centroids for every dt at once.

        Proposition 2.1 with m = 0 (graph flows go mode by mode, ``GraphCentroidFlow``).

        x(dt) = mean + p(dt) (x - mean) with the flow's own propagator p(dt).
        """
        flow, mean_x = self.system.flows[gi], self.coupling.groups[gi].mean_x
        if flow.mass == 0.0:            # propagator(dt)[1] = exp(-kappa dt / gamma), all at once
            decay = np.exp(-flow.kappa * np.array(dts) / flow.gamma)[:, None, None]
        else:
            decay = np.array([flow.propagator(dt)[1] for dt in dts])[:, None, None]
        xs = mean_x + decay * (gs.x - mean_x)
        return [(x, None) for x in xs]

    def _with_exact_centroids(self, st, dt, t):
        """``st`` at time t with decoupled centroids on their exact flow over dt (Prop. 2.1)."""
        if not self.system.model.centroids_exact:
            return State(t, st.groups)
        cents = exact_centroids(self.system, self.state, self.coupling, dt)
        return State(t, with_centroids(st.groups, cents))

    def _accepted_attempt(self):
        """(step, attempt result, growth factor) of the first attempt the error test accepts."""
        meth, y = self.method, self.state
        step = min(self.h, self.t_end - y.t)
        rejected = False
        while True:
            self._count_attempt()
            if not step >= STEP_FLOOR * max(1.0, abs(y.t)):
                if meth.rtol < TOLERANCE_FLOOR:
                    self._beyond_precision()
                raise PolymatchError(f"adaptive: step size fell to {step:.3g} at t = {y.t:.6g}; "
                                     "the scene is too stiff for an explicit method at this "
                                     "tolerance")
            with np.errstate(over="ignore", invalid="ignore"):
                result = self._attempt(self.chart, step, self.k0)
            err = result[-1]
            if math.isnan(err):
                self._beyond_precision()
            if err < 1.0:
                factor = MAX_FACTOR if err == 0 else min(MAX_FACTOR,
                                                         SAFETY * err ** meth.error_exponent)
                return step, result, (min(1.0, factor) if rejected else factor)
            self.nrejected += 1
            rejected = True
            step *= max(MIN_FACTOR, SAFETY * err ** meth.error_exponent)

    def step(self) -> list[State]:
        """Take one accepted step; return the states at the sample times it reached."""
        y = self.state
        step, (theta, raw_new, y_new, _), factor = self._accepted_attempt()
        self.nsteps += 1
        near_end = self.t_end - END_RTOL * max(1.0, abs(self.t_end))
        reached = self.t_end if y.t + step >= near_end else y.t + step
        first = self.next_sample
        stop = int(np.searchsorted(self.pending, reached, side="left"))   # pending < reached
        out = self._dense(step, theta, self.pending[first:stop]) if stop > first else []
        self.next_sample = stop
        self.state = y = self._with_exact_centroids(y_new, step, reached)
        self.coupling = self.system.couple(y.groups)
        self.chart = self.chart.at(y)
        self.k0 = self.chart.pack(raw_new)       # FSAL: raw rates at y_new are the new chart's k0
        self.h = min(step * factor, self.cap)
        if stop < len(self.pending) and self.pending[stop] == reached:
            self.next_sample += 1
            out.append(y)
        if reached >= self.t_end:
            self.status = FINISHED
        return out
