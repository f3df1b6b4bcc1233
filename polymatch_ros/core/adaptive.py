"""Adaptive step size: scipy's DOP853 tableau as a Munthe-Kaas method on SO(d).

Each step is taken in psi-coordinates (Cayley, or angles in 2-D) centred at the
current state, so the chart is re-centred every step and rotations stay in
SO(d) to round-off; the ODE for the increment Theta' = dpsi^{-1}_Theta(W) is
exact, so the 8th order and the embedded 5th/3rd-order error estimate of
DOP853 carry over unchanged.  Coefficients, error norm and step-size control
are scipy.integrate.DOP853's; the right-hand side uses the mean field, and
decoupled centroids are advanced by their exact flow (Proposition 2.1), so
they neither cost evaluations nor limit the step.

Centralised only: a distributed ensemble cannot agree on a step size without
an extra round per step.
"""

import math

import numpy as np
from scipy.integrate import DOP853

from .errors import PolymatchError
from .integrators import RKMK, MethodInfo, _exact_centroids, _nonempty
from .model import GroupState, State

SAFETY, MIN_FACTOR, MAX_FACTOR = 0.9, 0.2, 10.0


class AdaptiveLie:
    info = MethodInfo("adaptive", DOP853.order, DOP853.n_stages, 0, "adaptive", (1, 2),
                      "DOP853 (scipy's tableau and step control) in Cayley/angle coordinates, "
                      "re-centred every step; centralised only")

    def __init__(self, rtol, atol=None, max_steps=10_000_000):
        self.rtol = float(rtol)
        self.atol = float(rtol if atol is None else atol)
        self.max_steps = int(max_steps)
        n = DOP853.n_stages
        self._tableau = RKMK("dop853", DOP853.A[:n, :n], DOP853.B, DOP853.order, "")
        self.error_exponent = -1.0 / (DOP853.error_estimator_order + 1)
        self.nfev = 0
        self.steps = 0
        self.rejected = 0

    @property
    def name(self):
        return self.info.name

    # -- pieces ------------------------------------------------------------------
    def _rates(self, system, stage, thetas):
        coupling = system.couple(stage.groups)
        raw = system.rates(stage, coupling)
        self.nfev += 1
        return raw, system.in_chart(raw, thetas), coupling

    def _scales(self, system, y, y_new):
        """Per-group tuples of error scales matching (k_rot, k_x, k_v, k_w)."""
        out = []
        for gs, gn in zip(y.groups, y_new.groups):
            if not _nonempty(system, gs):
                out.append(None)
                continue
            sx = sv = sw = None
            if gs.w is not None:
                sw = self.atol + self.rtol * np.maximum(np.abs(gs.w), np.abs(gn.w))
            if not system.model.centroids_exact:
                sx = self.atol + self.rtol * np.maximum(np.abs(gs.x), np.abs(gn.x))
                if gs.v is not None:
                    sv = self.atol + self.rtol * np.maximum(np.abs(gs.v), np.abs(gn.v))
            out.append((self.atol + self.rtol, sx, sv, sw))
        return out

    def _error_norm(self, ks, h, scales):
        e5 = np.asarray(DOP853.E5)
        e3 = np.asarray(DOP853.E3)
        n5 = n3 = 0.0
        count = 0
        for gi, sc in enumerate(scales):
            if sc is None:
                continue
            for part in range(4):
                if ks[0][gi][part] is None:
                    continue
                terms = [k[gi][part] for k in ks]
                a5 = sum(c * t for c, t in zip(e5, terms) if c != 0.0) / sc[part]
                a3 = sum(c * t for c, t in zip(e3, terms) if c != 0.0) / sc[part]
                n5 += float(np.sum(a5 * a5))
                n3 += float(np.sum(a3 * a3))
                count += np.size(terms[0])
        if n5 == 0.0 and n3 == 0.0:
            return 0.0
        return abs(h) * n5 / math.sqrt((n5 + 0.01 * n3) * count)

    def _attempt(self, system, y, h, k0):
        tab = self._tableau
        ks = [k0]
        for i in range(1, DOP853.n_stages):
            thetas, stage = tab._stage(system, y, h, tab.a[i][:i], ks)
            ks.append(self._rates(system, stage, thetas)[1])
        thetas, y_new = tab._stage(system, y, h, tab.b, ks)
        raw_new, k_new, _ = self._rates(system, y_new, thetas)
        ks.append(k_new)
        return y_new, raw_new, self._error_norm(ks, h, self._scales(system, y, y_new))

    def _initial_step(self, system, y, k0, span):
        scales = self._scales(system, y, y)
        order = DOP853.order

        def rms(parts):
            tot, cnt = 0.0, 0
            for gi, sc in enumerate(scales):
                if sc is None:
                    continue
                for p in range(4):
                    if parts[gi][p] is not None:
                        ref = k0[gi][p]
                        val = np.broadcast_to(parts[gi][p] / sc[p], np.shape(ref))
                        tot += float(np.sum(val ** 2))
                        cnt += np.size(ref)
            return math.sqrt(tot / max(cnt, 1))

        d1 = rms(k0)
        size = [None if gs is None or sc is None else
                (1.0, None if sc[1] is None else np.abs(gs.x), None if sc[2] is None else np.abs(gs.v),
                 None if sc[3] is None else np.abs(gs.w))
                for gs, sc in zip(y.groups, scales)]      # rotations have unit size
        d0 = rms(size)
        h0 = 1e-6 if (d1 < 1e-5) else 0.01 * d0 / d1
        h0 = min(h0, span)
        thetas, stage = self._tableau._stage(system, y, h0, [1.0], [k0])
        k1 = self._rates(system, stage, thetas)[1]
        diff = [None if a is None else tuple(None if u is None else (v - u) / h0 for u, v in zip(a, b))
                for a, b in zip(k0, k1)]
        d2 = rms(diff)
        if max(d1, d2) <= 1e-15:
            h1 = max(1e-6, h0 * 1e-3)
        else:
            h1 = (0.01 / max(d1, d2)) ** (1.0 / (order + 1))
        return min(100 * h0, h1, span)

    # -- driver --------------------------------------------------------------------
    def integrate(self, system, y, times, on_sample=None):
        """Advance y through the increasing ``times``; ``on_sample(state)`` at each; returns the last state."""
        times = [t for t in times if t > y.t]
        if not times:
            return y
        coupling = system.couple(y.groups)
        k0 = system.rates(y, coupling)
        self.nfev += 1
        h = self._initial_step(system, y, k0, times[-1] - y.t)
        for target in times:
            while y.t < target:
                if self.steps >= self.max_steps:
                    raise PolymatchError(f"adaptive: {self.max_steps} steps reached at t = {y.t:.6g} of "
                                         f"{times[-1]:g}; raise integrator.max_steps or use a fixed dt")
                clipped = target - y.t < h
                step = min(h, target - y.t)
                rejected = False
                while True:
                    if step < 1e-12 * max(1.0, abs(y.t)):
                        raise PolymatchError(f"adaptive: step size fell to {step:.3g} at t = {y.t:.6g}; the "
                                             "scene is too stiff for an explicit method at this tolerance")
                    y_new, k_new, err = self._attempt(system, y, step, k0)
                    if err < 1.0:
                        factor = MAX_FACTOR if err == 0 else min(MAX_FACTOR, SAFETY * err ** self.error_exponent)
                        if rejected:
                            factor = min(1.0, factor)
                        break
                    self.rejected += 1
                    rejected = True
                    step *= max(MIN_FACTOR, SAFETY * err ** self.error_exponent)
                self.steps += 1
                reached = y.t + step
                if reached >= target - 1e-13 * max(1.0, abs(target)):
                    reached = target
                if system.model.centroids_exact:
                    cents = _exact_centroids(system, y, coupling, step)
                    y_new = State(reached, tuple(
                        gs if not _nonempty(system, gs) else GroupState(c[0], gs.rot, c[1], gs.w)
                        for gs, c in zip(y_new.groups, cents)))
                else:
                    y_new = State(reached, y_new.groups)
                coupling = system.couple(y_new.groups)
                k0 = k_new                      # FSAL: raw rates at y_new, chart re-centred
                y = y_new
                if rejected or not clipped:
                    h = step * factor           # a clipped, accepted step keeps the proposal
            if on_sample is not None:
                on_sample(y)
        return y
