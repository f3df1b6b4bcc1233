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
"""

import math

import numpy as np
from scipy.integrate import DOP853

from .errors import PolymatchError
from .integrators import MethodInfo, _exact_centroids, rk_stability, test_matrices
from .model import GroupState, State

SAFETY, MIN_FACTOR, MAX_FACTOR = 0.9, 0.2, 10.0
N_STAGES = DOP853.n_stages


class _Chart:
    """Flat increment coordinates centred at the state y: per group rot, [x, v,] [w]."""

    def __init__(self, system, y):
        self.system, self.y = system, y
        grp, model = system.group, system.model
        self.parts = []
        pos = 0
        base, is_rot = [], []
        for gi, gs in enumerate(y.groups):
            if gs is None or grp.count(gs.rot) == 0:
                continue
            fields = [("rot", grp.algebra_zeros(grp.count(gs.rot)))]
            if not model.centroids_exact:
                fields.append(("x", gs.x))
                if model.order == 2:
                    fields.append(("v", gs.v))
            if model.order == 2:
                fields.append(("w", gs.w))
            for kind, value in fields:
                size = value.size
                self.parts.append((gi, kind, value.shape, slice(pos, pos + size)))
                base.append(np.ravel(value))
                is_rot.append(np.full(size, kind == "rot"))
                pos += size
        self.n = pos
        self.base = np.concatenate(base) if base else np.zeros(0)        # 0 in the rotation slots
        self.is_rot = np.concatenate(is_rot) if is_rot else np.zeros(0, dtype=bool)
        self.base_size = np.where(self.is_rot, 1.0, np.abs(self.base))   # rotations have unit size

    def state(self, vec):
        """(State at psi(vec) . y, per-group Theta) — the stage the right-hand side is evaluated at."""
        grp = self.system.group
        groups = list(self.y.groups)
        thetas = [None] * len(groups)
        if len(self.parts) == 1:                      # one group, rotations only (first order)
            gi, _, shape, _ = self.parts[0]
            gs = groups[gi]
            thetas[gi] = theta = vec.reshape(shape)
            groups[gi] = GroupState(gs.x, grp.retract(theta, gs.rot), gs.v, gs.w)
            return State(self.y.t, tuple(groups)), thetas
        for gi, kind, shape, sl in self.parts:
            piece = vec[sl].reshape(shape)
            gs = groups[gi]
            if kind == "rot":
                thetas[gi] = piece
                groups[gi] = GroupState(gs.x, grp.retract(piece, gs.rot), gs.v, gs.w)
            elif kind == "x":
                groups[gi] = GroupState(self.y.groups[gi].x + piece, gs.rot, gs.v, gs.w)
            elif kind == "v":
                groups[gi] = GroupState(gs.x, gs.rot, self.y.groups[gi].v + piece, gs.w)
            else:
                groups[gi] = GroupState(gs.x, gs.rot, gs.v, self.y.groups[gi].w + piece)
        return State(self.y.t, tuple(groups)), thetas

    _INDEX = {"rot": 0, "x": 1, "v": 2, "w": 3}

    def pack(self, rates):
        if len(self.parts) == 1:                      # one group, rotations only: no copy needed
            gi, kind, _, _ = self.parts[0]
            return rates[gi][self._INDEX[kind]].reshape(-1)
        out = np.empty(self.n)
        for gi, kind, shape, sl in self.parts:
            out[sl] = rates[gi][self._INDEX[kind]].reshape(-1)
        return out


class AdaptiveLie:
    info = MethodInfo("adaptive", DOP853.order, N_STAGES, 0, "adaptive", (1, 2),
                      "DOP853 (scipy's tableau, step control, dense output) in Cayley/angle coordinates, "
                      "re-centred every step; centralised only")

    def __init__(self, rtol, atol=None, max_steps=10_000_000):
        self.rtol = float(rtol)
        self.atol = float(rtol if atol is None else atol)
        self.max_steps = int(max_steps)
        self.error_exponent = -1.0 / (DOP853.error_estimator_order + 1)
        self.nfev = 0
        self.steps = 0
        self.rejected = 0
        self.A, self.B = DOP853.A[:N_STAGES, :N_STAGES], DOP853.B
        self._rows = [np.ascontiguousarray(self.A[s, :s]) for s in range(1, N_STAGES)]
        self.E3, self.E5 = DOP853.E3, DOP853.E5

    @property
    def name(self):
        return self.info.name

    def step_cap(self, model):
        """0.9 x the largest h at which DOP853 is linearly stable on the model's test matrices.

        Near consensus the error estimate lets the step grow until it hovers at the
        stability boundary, which keeps a converged ensemble from staying converged;
        no step beyond the cap can be accurate anyway.  Returns (cap, binding cause).
        """
        a, b = self.A, self.B
        best = (np.inf, "")
        for _, mat, cause in test_matrices(model):
            lam = np.linalg.eigvals(np.atleast_2d(mat))
            rate = float(np.max(np.abs(lam)))
            if rate == 0.0:
                continue
            lo, hi = 0.0, 20.0 / rate
            for _ in range(60):
                mid = 0.5 * (lo + hi)
                if np.all(np.abs(rk_stability(a, b, mid * lam)) <= 1.0):
                    lo = mid
                else:
                    hi = mid
            if 0.9 * lo < best[0]:
                best = (0.9 * lo, cause)
        return best

    def _fun(self, chart, vec):
        stage, thetas = chart.state(vec)
        system = chart.system
        raw = system.rates(stage, system.couple(stage.groups, first_stage=False))
        self.nfev += 1
        return chart.pack(system.in_chart(raw, thetas)), raw, stage

    def _error_norm(self, K, h, scale):
        err5 = (K.T @ self.E5) / scale
        err3 = (K.T @ self.E3) / scale
        n5, n3 = float(err5 @ err5), float(err3 @ err3)
        if n5 == 0.0 and n3 == 0.0:
            return 0.0
        return abs(h) * n5 / math.sqrt((n5 + 0.01 * n3) * len(scale))

    def _attempt(self, chart, h, k0):
        K = np.empty((N_STAGES + 1, chart.n))
        K[0] = k0
        for s, row in enumerate(self._rows, start=1):
            K[s] = self._fun(chart, (row @ K[:s]) * h)[0]
        theta = (K[:N_STAGES].T @ self.B) * h
        K[N_STAGES], raw_new, y_new = self._fun(chart, theta)
        new_size = np.where(chart.is_rot, 1.0, np.abs(chart.base + theta))
        scale = self.atol + self.rtol * np.maximum(chart.base_size, new_size)
        return theta, K, raw_new, y_new, self._error_norm(K, h, scale)

    def _initial_step(self, chart, k0, span):
        scale = self.atol + self.rtol * chart.base_size
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

    def _dense(self, chart, K, h, theta, k_end, y, coupling, times, on_sample):
        """Interpolate (DOP853's continuous extension in the chart) at the sample times in the step."""
        Kx = np.empty((N_STAGES + 1 + len(DOP853.C_EXTRA), chart.n))
        Kx[:N_STAGES + 1] = K
        for s, (a, c) in enumerate(zip(DOP853.A_EXTRA, DOP853.C_EXTRA), start=N_STAGES + 1):
            Kx[s] = self._fun(chart, (Kx[:s].T @ a[:s]) * h)[0]
        F = np.empty((DOP853.D.shape[0] + 3, chart.n))
        F[0] = theta
        F[1] = h * Kx[0] - theta
        F[2] = 2 * theta - h * (k_end + Kx[0])
        F[3:] = h * (DOP853.D @ Kx)
        system = chart.system
        for t in times:
            x = (t - y.t) / h
            val = np.zeros(chart.n)
            for i, f in enumerate(reversed(F)):
                val += f
                val *= x if i % 2 == 0 else 1 - x
            st, _ = chart.state(val)
            if system.model.centroids_exact:
                cents = _exact_centroids(system, y, coupling, t - y.t)
                st = State(t, tuple(gs if c is None else GroupState(c[0], gs.rot, c[1], gs.w)
                                    for gs, c in zip(st.groups, _present(system, st, cents))))
            on_sample(State(t, st.groups))

    # -- driver --------------------------------------------------------------------
    def integrate(self, system, y, times, on_sample=None, on_step=None):
        """Advance y to the last of the increasing ``times``.

        ``on_sample(state)`` is called at each of ``times`` (interpolated inside a step),
        ``on_step(state)`` after every accepted step.
        """
        times = [float(t) for t in times if t > y.t]
        if not times:
            return y
        t_end = times[-1]
        cap, cause = self.step_cap(system.model)
        if (t_end - y.t) / cap > self.max_steps:
            raise PolymatchError(f"adaptive: the scene is stiff ({cause}): an explicit method needs at least "
                                 f"{(t_end - y.t) / cap:.2g} steps to reach t = {t_end:g} (max_steps = "
                                 f"{self.max_steps}); use etd2 for stiff damping, a shorter t_end, or a "
                                 f"larger integrator.max_steps")
        coupling = system.couple(y.groups)
        chart = _Chart(system, y)
        k0 = chart.pack(system.rates(y, coupling))
        self.nfev += 1
        h = min(self._initial_step(chart, k0, t_end - y.t), cap)
        pending = list(times)
        while y.t < t_end:
            if self.steps >= self.max_steps:
                raise PolymatchError(f"adaptive: {self.max_steps} steps reached at t = {y.t:.6g} of "
                                     f"{t_end:g}; raise integrator.max_steps or use a fixed dt")
            step = min(h, t_end - y.t)
            rejected = False
            while True:
                if step < 1e-12 * max(1.0, abs(y.t)):
                    raise PolymatchError(f"adaptive: step size fell to {step:.3g} at t = {y.t:.6g}; the "
                                         "scene is too stiff for an explicit method at this tolerance")
                theta, K, raw_new, y_new, err = self._attempt(chart, step, k0)
                if err < 1.0:
                    factor = MAX_FACTOR if err == 0 else min(MAX_FACTOR, SAFETY * err ** self.error_exponent)
                    if rejected:
                        factor = min(1.0, factor)
                    break
                self.rejected += 1
                rejected = True
                step *= max(MIN_FACTOR, SAFETY * err ** self.error_exponent)
            self.steps += 1
            reached = t_end if y.t + step >= t_end - 1e-13 * max(1.0, abs(t_end)) else y.t + step
            inside = [t for t in pending if t < reached]
            pending = [t for t in pending if t >= reached]
            if inside and on_sample is not None:
                self._dense(chart, K, step, theta, K[N_STAGES], y, coupling, inside, on_sample)
            if system.model.centroids_exact:
                cents = _exact_centroids(system, y, coupling, step)
                y_new = State(reached, tuple(gs if c is None else GroupState(c[0], gs.rot, c[1], gs.w)
                                             for gs, c in zip(y_new.groups, _present(system, y_new, cents))))
            else:
                y_new = State(reached, y_new.groups)
            y = y_new
            if on_step is not None:
                on_step(y)
            coupling = system.couple(y.groups)
            chart = _Chart(system, y)
            k0 = chart.pack(raw_new)               # FSAL: raw rates at y_new are the new chart's k0
            h = min(step * factor, cap)
            if pending and pending[0] == reached:
                pending.pop(0)
                if on_sample is not None:
                    on_sample(y)
        return y


def _present(system, state, cents):
    return [None if gs is None or system.group.count(gs.rot) == 0 else c for gs, c in zip(state.groups, cents)]
