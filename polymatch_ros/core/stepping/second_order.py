"""Methods for the second-order model (A-1) only: exponential integrators and a splitting.

exponential  For stiff damping m/gamma -> 0: the damping is integrated exactly (scalar
             phi-functions), the coupling explicitly.  Runs at ordinary dt when m = 1e-8
             and tends to the first-order model (A-2).
splitting    Strang splitting damp/kick/drift/kick/damp.  For gamma = 0 it is symplectic
             (the Cayley drift is the exact flow of a modified kinetic energy), so the energy
             of Proposition 2.2 has no secular drift.
"""

import math
from collections.abc import Callable
from functools import lru_cache
from typing import Any

import numpy as np

from ..model import Coupling, GroupState, State, System
from .solver import Method, MethodInfo, Stepper, advance_active

#: |z| below which phi_k(z) is summed as a series (expm1-based formulas cancel there)
PHI_SERIES_RADIUS = 1.0


def phi_functions(z: float) -> tuple[float, float, float, float]:
    """(e^z, phi_1(z), phi_2(z), phi_3(z)) for real z, accurate for all z <= 0 and small z > 0.

    Kept per z (``_phi_functions``): a run's steps take a handful of distinct h.
    """
    return _phi_functions(float(z))


@lru_cache(maxsize=64)
def _phi_functions(z: float) -> tuple[float, float, float, float]:
    if abs(z) < PHI_SERIES_RADIUS:
        phis = []
        for k in (1, 2, 3):
            term = 1.0 / math.factorial(k)
            total = term
            for j in range(1, 30):
                term *= z / (j + k)
                total += term
            phis.append(total)
        return math.exp(z), phis[0], phis[1], phis[2]
    e = math.exp(z)
    p1 = math.expm1(z) / z
    p2 = (p1 - 1.0) / z
    p3 = (p2 - 0.5) / z
    return e, p1, p2, p3


def _two_by_two_radius(step_map: Callable[[float, float], Any]) -> float:
    """Spectral radius of the linear map (x0, v0) -> step_map(x0, v0) on R^2."""
    amp = np.empty((2, 2))
    for col, (x0, v0) in enumerate(((1.0, 0.0), (0.0, 1.0))):
        amp[:, col] = step_map(x0, v0)
    return float(np.max(np.abs(np.linalg.eigvals(amp))))


class ExponentialLie(Method):
    """Exponential Lie-Euler (order 1) and ETD2-Lie (order 2) for the second-order model (A-1).

    With lambda = gamma/m and N(O) = kappa/(2Nm)(S O^T - O S^T), the damping is solved exactly:
        W(t) = e^{-lambda t} W_n + int_0^t e^{-lambda (t-s)} N(s) ds,
        O_{n+1} = psi(int_0^h W) O_n,
    with N frozen (order 1) or linear between N(O_n) and N(O_pred) (order 2, Cox-Matthews ETD2RK):
        W_{n+1} = e W_n + h phi1 N_n + h phi2 (N_p - N_n)
        Theta   = h phi1 W_n + h^2 phi2 N_n + h^2 phi3 (N_p - N_n)
    As m -> 0 this tends to Heun's method for the first-order model (A-2); stable at any m.
    """

    def __init__(self, order: int) -> None:
        name = "etd1" if order == 1 else "etd2"
        summary = ("exponential Lie-Euler: damping exact, coupling frozen; stiff m/gamma"
                   if order == 1 else
                   "ETD2-Lie: damping exact, coupling linear in time; stiff m/gamma -> "
                   "first-order limit")
        self.info = MethodInfo(name, order, order, order, "exponential", (2,), summary)

    def _forces(self, system, stage, coupling):
        """Per group (N(O) of the rotations, centroid force / m or None), None when inactive."""
        m = system.model

        def forces(gi, gs):
            n_rot = system.rotation_rate(gi, gs.rot, coupling) / m.mass
            n_x = None if m.centroids_exact else system.centroid_force(gi, gs.x, coupling) / m.mass
            return n_rot, n_x
        return system.per_active_group(stage.groups, forces)

    @staticmethod
    def _predict(system, y, h, phis, f1):
        """Coupling frozen at its step-start value N_n (the exponential Lie-Euler step)."""
        e, p1, p2, _ = phis
        out = []
        for gs, f in zip(y.groups, f1):
            if f is None:
                out.append(gs)
                continue
            theta = h * p1 * gs.w + h * h * p2 * f[0]
            w = e * gs.w + h * p1 * f[0]
            x, v = gs.x, gs.v
            if f[1] is not None:
                x = gs.x + h * p1 * gs.v + h * h * p2 * f[1]
                v = e * gs.v + h * p1 * f[1]
            out.append(GroupState(x, system.group.retract(theta, gs.rot), v, w))
        return State(y.t, tuple(out))

    @staticmethod
    def _correct(system, y, h, phis, f1, f2):
        """Coupling linear in time between N_n and N(O_pred) (ETD2RK's corrector)."""
        e, p1, p2, p3 = phis
        out = []
        for gs, a, b in zip(y.groups, f1, f2):
            if a is None:
                out.append(gs)
                continue
            dn = b[0] - a[0]
            theta = h * p1 * gs.w + h * h * (p2 * a[0] + p3 * dn)
            w = e * gs.w + h * (p1 * a[0] + p2 * dn)
            x, v = gs.x, gs.v
            if a[1] is not None:
                dx = b[1] - a[1]
                x = gs.x + h * p1 * gs.v + h * h * (p2 * a[1] + p3 * dx)
                v = e * gs.v + h * (p1 * a[1] + p2 * dx)
            out.append(GroupState(x, system.group.retract(theta, gs.rot), v, w))
        return State(y.t, tuple(out))

    def stages(self, system: System, y: State, h: float, coupling: Coupling,
               centroids: list | None) -> Stepper:
        m = system.model
        phis = phi_functions(-m.gamma * h / m.mass)
        f1 = self._forces(system, y, coupling)
        pred = self._predict(system, y, h, phis, f1)
        if self.info.order == 1:
            return pred
        c2 = yield from system.evaluate(pred)
        return self._correct(system, y, h, phis, f1, self._forces(system, pred, c2))

    def spectral_radius(self, h: float, a: np.ndarray) -> float:
        """Apply the scheme to x' = v, v' = -lambda v + n x (the 2x2 test system a)."""
        a = np.atleast_2d(np.asarray(a, dtype=float))
        lam, n = -a[1, 1], a[1, 0]
        e, p1, p2, p3 = phi_functions(-lam * h)

        def step_map(x0, v0):
            n1 = n * x0
            xp = x0 + h * p1 * v0 + h * h * p2 * n1
            vp = e * v0 + h * p1 * n1
            if self.info.order == 2:
                dn = n * xp - n1
                xp = x0 + h * p1 * v0 + h * h * (p2 * n1 + p3 * dn)
                vp = e * v0 + h * (p1 * n1 + p2 * dn)
            return xp, vp
        return _two_by_two_radius(step_map)


class LieVerlet(Method):
    """Damp(h/2) Kick(h/2) Drift(h) Kick(h/2) Damp(h/2), with a Cayley/exp drift O <- psi(h W) O.

    Second order; one mean-field evaluation per step (the last kick's is the next step's
    first: FSAL, cached on the returned state).  With gamma = 0 every sub-step is a
    symplectic map, so the energy of Proposition 2.2 oscillates at O(h^2) without drift.
    """

    info = MethodInfo("lie_verlet", 2, 1, 1, "splitting", (2,),
                      "Strang splitting damp/kick/drift/kick/damp; symplectic for gamma = 0, "
                      "one exchange per step")

    @staticmethod
    def _kick_drift(system, y, h, damp, c0, centroids):
        """Damp and kick by h/2 from the step start, drift by h: (mid state, half-step v)."""
        m = system.model

        def kick_drift(gi, gs):
            w = damp * gs.w + (0.5 * h / m.mass) * system.rotation_rate(gi, gs.rot, c0)
            rot = system.group.retract(h * w, gs.rot)
            if centroids is not None:
                x, v = centroids[gi]
                hv = None
            else:
                hv = damp * gs.v + (0.5 * h / m.mass) * system.centroid_force(gi, gs.x, c0)
                x, v = gs.x + h * hv, hv
            return GroupState(x, rot, v, w), hv
        mid, half_v = advance_active(system, y.groups, kick_drift)
        return State(y.t + h, mid), half_v

    def stages(self, system: System, y: State, h: float, coupling: Coupling,
               centroids: list | None) -> Stepper:
        m = system.model
        damp = math.exp(-m.gamma * h / (2.0 * m.mass))
        mid, half_v = self._kick_drift(system, y, h, damp, coupling, centroids)
        c1 = yield from system.evaluate(mid, first_stage=True)

        def kick_damp(gi, gs):
            w = damp * (gs.w + (0.5 * h / m.mass) * system.rotation_rate(gi, gs.rot, c1))
            v = gs.v
            if half_v[gi] is not None:
                v = damp * (half_v[gi] + (0.5 * h / m.mass) * system.centroid_force(gi, gs.x, c1))
            return GroupState(gs.x, gs.rot, v, w), None
        end, _ = advance_active(system, mid.groups, kick_damp)
        return State(y.t + h, end, coupling=c1)

    def spectral_radius(self, h: float, a: np.ndarray) -> float:
        a = np.atleast_2d(np.asarray(a, dtype=float))
        lam, n = -a[1, 1], a[1, 0]
        damp = math.exp(-lam * h / 2.0)

        def step_map(x0, v0):
            v = damp * v0 + 0.5 * h * n * x0
            x = x0 + h * v
            return x, damp * (v + 0.5 * h * n * x)
        return _two_by_two_radius(step_map)
