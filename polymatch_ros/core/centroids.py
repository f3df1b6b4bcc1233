"""Centroid dynamics: the exact flow of Proposition 2.1 and the F-2 inter-group force.

Centroids never couple to rotations.  Inside one group without an inter-group
potential their equations are linear and ``CentroidFlow`` solves them exactly
(``GraphCentroidFlow`` on an undirected communication graph, mode by mode of its
Laplacian); across groups (F-2) ``pair_force`` is the force of V = kappa_2/2 (|x - y| - L)^2.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from .graph import Graph


class CentroidFlow:
    """Exact flow of m x'' = -gamma x' + kappa (mu - x) over a step h (Proposition 2.1).

    The mean mu moves by its own momentum (kappa = 0 mode), each deviation
    x_i - mu by the damped oscillator with stiffness kappa.  For m = 0 the
    deviation decays as exp(-kappa h / gamma) and mu is constant.  Formulas are
    written with phi_1(z) = expm1(z)/z so they stay accurate for m -> 0, near
    critical damping, and for gamma = 0.
    """

    def __init__(self, mass: float, gamma: float, kappa: float) -> None:
        self.mass, self.gamma, self.kappa = float(mass), float(gamma), float(kappa)
        self._cache: dict[float, tuple] = {}

    @staticmethod
    def _roots(m: float, gamma: float, k: float) -> tuple[complex, complex]:
        """Roots of m l^2 + gamma l + k = 0, computed without cancellation."""
        disc = gamma * gamma - 4.0 * m * k
        if disc >= 0:
            sq = np.sqrt(disc)
            q = -0.5 * (gamma + sq)
            fast = q / m
            slow = k / q if q != 0 else 0.0
            return complex(fast), complex(slow)
        sq = np.sqrt(-disc)
        return complex(-gamma, sq) / (2 * m), complex(-gamma, -sq) / (2 * m)

    def _matrix(self, k: float, h: float) -> np.ndarray:
        m, gamma = self.mass, self.gamma
        l1, l2 = self._roots(m, gamma, k)
        delta = l1 - l2
        e1, e2 = np.exp(l1 * h), np.exp(l2 * h)
        z = delta * h
        phi1 = np.expm1(z) / z if abs(z) > 1e-12 else 1.0 + z / 2
        p = h * e2 * phi1                    # (e1 - e2) / (l1 - l2)
        if abs(z) > 1.0:                     # well separated roots: no cancellation
            xx = (l1 * e2 - l2 * e1) / delta
            vv = (l1 * e1 - l2 * e2) / delta
        else:
            xx = e2 - l2 * p
            vv = e2 + l1 * p
        vx = -(k / m) * p
        return np.array([[xx, p], [vx, vv]]).real

    def propagator(self, h: float) -> tuple:
        """(mean 2x2, deviation 2x2) for the second-order model; scalars for the first."""
        key = float(h)
        if key not in self._cache:
            if self.mass == 0.0:
                self._cache[key] = (1.0, float(np.exp(-self.kappa * h / self.gamma)))
            else:
                self._cache[key] = (self._matrix(0.0, h), self._matrix(self.kappa, h))
            if len(self._cache) > 64:
                self._cache.pop(next(iter(self._cache)))
        return self._cache[key]

    def advance(self, x: np.ndarray, v: np.ndarray | None, mean_x: np.ndarray,
                mean_v: np.ndarray | None, h: float) -> tuple[np.ndarray, np.ndarray | None]:
        """New (x, v) of the given rows, from the group means at the start of the step."""
        p0, pk = self.propagator(h)
        dx = x - mean_x
        if self.mass == 0.0:
            return mean_x + pk * dx, None
        assert v is not None and mean_v is not None, "the second-order model has velocities"
        dv = v - mean_v
        (m_xx, m_xv), (m_vx, m_vv) = p0.tolist()        # floats: cheaper factors than items
        (d_xx, d_xv), (d_vx, d_vv) = pk.tolist()
        mx = m_xx * mean_x + m_xv * mean_v
        mv = m_vx * mean_x + m_vv * mean_v
        return (mx + d_xx * dx + d_xv * dv,
                mv + d_vx * dx + d_vv * dv)


def mode_propagators(mass: float, gamma: float, stiffness: np.ndarray, h: float) -> tuple:
    """CentroidFlow's 2x2 propagator of m y'' = -gamma y' - k y, per k of an array: xx, xv, vx, vv.

    The same roots and phi_1 formulas, vectorised (complex arithmetic covers both the
    over- and the under-damped modes).
    """
    k = np.asarray(stiffness, dtype=float)
    sq = np.sqrt((gamma * gamma - 4.0 * mass * k).astype(complex))
    q = -0.5 * (gamma + sq)
    l1 = q / mass
    l2 = np.divide(k, q, out=np.zeros_like(q), where=q != 0)
    delta = l1 - l2
    e1, e2 = np.exp(l1 * h), np.exp(l2 * h)
    z = delta * h
    small = np.abs(z) <= 1e-12
    phi1 = np.where(small, 1.0 + z / 2, np.expm1(z) / np.where(small, 1.0, z))
    p = h * e2 * phi1                        # (e1 - e2) / (l1 - l2)
    far = np.abs(z) > 1.0
    safe = np.where(far, delta, 1.0)
    xx = np.where(far, (l1 * e2 - l2 * e1) / safe, e2 - l2 * p)
    vv = np.where(far, (l1 * e1 - l2 * e2) / safe, e2 + l1 * p)
    return xx.real, p.real, (-(k / mass) * p).real, vv.real


class GraphCentroidFlow:
    """Exact centroid flow on an undirected graph: Proposition 2.1 mode by mode.

    m x'' = -gamma x' - kappa L x (m = 0: gamma x' = -kappa L x) with L the graph's
    Laplacian (``Graph.laplacian``).  ``Graph.laplacian_modes`` gives L = V diag(lambda)
    V^T diag(b), so y = V^T diag(b) x splits into scalar modes of stiffness kappa lambda_j,
    each advanced exactly (the zero modes, one per component, keep their mean moving by
    its momentum).  O(N^3) once, O(N^2 d) per step; ``rows`` are the rows it returns.
    """

    def __init__(self, mass: float, gamma: float, kappa: float, graph: Graph,
                 rows: Sequence[int] | np.ndarray | None = None) -> None:
        self.mass, self.gamma, self.kappa = float(mass), float(gamma), float(kappa)
        self.graph = graph
        self.rows = None if rows is None else np.asarray(rows, dtype=int)
        self._cache: dict[float, tuple] = {}

    def propagator(self, h: float) -> tuple:
        """Per-mode coefficients over h: (decay,) first order, (xx, xv, vx, vv) second."""
        key = float(h)
        if key not in self._cache:
            lam = self.graph.laplacian_modes[0]
            if self.mass == 0.0:
                self._cache[key] = (np.exp(-self.kappa * lam * h / self.gamma),)
            else:
                self._cache[key] = mode_propagators(self.mass, self.gamma, self.kappa * lam, h)
            if len(self._cache) > 64:
                self._cache.pop(next(iter(self._cache)))
        return self._cache[key]

    def advance_group(self, x: np.ndarray, v: np.ndarray | None, h: float,
                      index: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]:
        """New (x, v) of ``rows`` from the group's (x, v) at the step start (rows ``index``)."""
        _, vec, analysis = self.graph.laplacian_modes
        synthesis = vec if self.rows is None else vec[self.rows]
        if index is not None:
            analysis = analysis[:, index]
        coef = self.propagator(h)
        y = analysis @ x
        if self.mass == 0.0:
            return synthesis @ (coef[0][:, None] * y), None
        w = analysis @ v
        xx, xv, vx, vv = (c[:, None] for c in coef)
        return synthesis @ (xx * y + xv * w), synthesis @ (vx * y + vv * w)


def pair_force(x: np.ndarray, y: np.ndarray, kappa_2: float, L: float,
               chunk: int = 1 << 20) -> np.ndarray:
    """F-2 force on each row of x from the centroids y of another group (N_y = len(y)).

        F_i = kappa_2 / N_y  sum_l (|y_l - x_i| - L) (y_l - x_i) / |y_l - x_i|

    which is -grad_x of (kappa_2 / N_y) sum_l V(x_i, y_l).  At exactly coincident
    centroids the direction is undefined (the paper's force is 0/0); we take the
    force of such a pair to be zero, the average of the force over all directions
    of approach.  It is finite everywhere, never NaN, and the pair separates as
    soon as any other agent moves either centroid.
    """
    out = np.zeros_like(x)
    if len(y) == 0 or len(x) == 0:
        return out
    rows = max(1, chunk // (len(y) * x.shape[1]))
    for a in range(0, len(x), rows):
        diff = y[None, :, :] - x[a:a + rows, None, :]
        r = np.sqrt(np.sum(diff * diff, axis=2))
        with np.errstate(divide="ignore", invalid="ignore"):
            coef = np.where(r > 0, (r - L) / np.where(r > 0, r, 1.0), 0.0)
        out[a:a + rows] = np.einsum("ij,ijk->ik", coef, diff)
    return out * (kappa_2 / len(y))
