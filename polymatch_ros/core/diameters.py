"""Diameters of large point sets in O(N) or O(N log N): exact where cheap, else two-sided bounds.

The exact pairwise diameter (``metrics.point_set_diameter``) is near-linear on spread-out
points but O(N^2) on clustered ones.  What a check before a run (the certificate of
``core.certificate``) needs is often only a side of a threshold, so beyond
``EXACT_PAIRS_UP_TO`` points it uses:

- points in at most 3 dimensions: the farthest pair lies on the convex hull (scipy's Qhull,
  O(N log N)); when the hull has at most ``EXACT_PAIRS_UP_TO`` vertices the diameter is the
  exact one of the hull's vertices;
- otherwise bounds from the distances to the mean c:
  max_i |p_i - c| <= D <= 2 max_i |p_i - c| (triangle inequality), the upper one also capped
  by the bounding box's diagonal, the lower one raised by two farthest-point sweeps (each an
  actual pair's distance);
- rotations of SO(2): |O_i - O_j|_F = 2 sqrt 2 sin(delta_ij / 2), delta_ij the angle between
  them; within an open half-circle of arc A the largest delta is A (exact, O(N log N));
  spread over A >= pi, some pair is at least pi/2 apart (were every pair closer, all would lie
  within an open half-circle about any one of them), so D >= 2 sqrt 2 sin(pi/4) = 2.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .metrics import point_set_diameter

#: up to this many points (or hull vertices) the diameter is the exact pairwise one; the
#: pruned pairwise search takes a few milliseconds here even on clustered points
EXACT_PAIRS_UP_TO = 2048


@dataclass(frozen=True)
class Diameter:
    """lower <= the diameter <= upper; equal when it is exact."""

    lower: float
    upper: float

    @property
    def exact(self) -> bool:
        return self.lower == self.upper

    def text(self, name: str) -> str:
        """``D = 1.5`` or ``1.2 <= D <= 2.4 (bounds)``, as the certificate prints it."""
        if self.exact:
            return f"{name} = {self.upper:.3g}"
        return f"{self.lower:.3g} <= {name} <= {self.upper:.3g} (bounds)"


def diameter(points: np.ndarray, exact_up_to: int = EXACT_PAIRS_UP_TO) -> Diameter:
    """The diameter of points (N, k): exact up to ``exact_up_to`` points or hull vertices,
    else bounds, in O(N k) (and O(N log N) for k <= 3)."""
    p = np.asarray(points, dtype=float)
    n = p.shape[0]
    if n <= exact_up_to:
        exact = point_set_diameter(p)
        return Diameter(exact, exact)
    q = p - p.mean(axis=0)
    if q.shape[1] == 1:
        span = float(q.max() - q.min())
        return Diameter(span, span)
    if q.shape[1] <= 3:
        hull = _hull_vertices(q)
        if hull is not None and len(hull) <= exact_up_to:
            exact = point_set_diameter(q[hull])
            return Diameter(exact, exact)
    return _bounds(q)


def _hull_vertices(q: np.ndarray) -> np.ndarray | None:
    """Indices of the convex hull's vertices, or None when Qhull cannot build it (flat sets)."""
    from scipy.spatial import ConvexHull, QhullError

    try:
        return np.asarray(ConvexHull(q).vertices)
    except (QhullError, ValueError):
        return None


def _bounds(q: np.ndarray) -> Diameter:
    """Bounds of the diameter of centred points q (module docstring), O(N k)."""
    r2 = np.einsum("ij,ij->i", q, q)
    radius = math.sqrt(float(r2.max()))
    box = math.sqrt(float(np.sum((q.max(axis=0) - q.min(axis=0)) ** 2)))
    lower = radius
    i = int(np.argmax(r2))
    for _ in range(2):                   # farthest-point sweeps: each gives an actual pair
        diff = q - q[i]
        d2 = np.einsum("ij,ij->i", diff, diff)
        j = int(np.argmax(d2))
        lower = max(lower, math.sqrt(float(d2[j])))
        i = j
    return Diameter(lower, max(lower, min(2.0 * radius, box)))


def circle_arc(theta: np.ndarray) -> tuple[np.ndarray, float]:
    """Phases lifted to reals inside the shortest arc holding them all, and its length."""
    t = np.mod(theta, 2 * math.pi)
    order = np.sort(t)
    if len(order) < 2:
        return t, 0.0
    gaps = np.diff(np.concatenate([order, [order[0] + 2 * math.pi]]))
    k = int(np.argmax(gaps))
    start = order[(k + 1) % len(order)]          # the arc begins after the largest gap
    lifted = np.mod(t - start, 2 * math.pi)
    return lifted, float(2 * math.pi - gaps[k])


def planar_rotation_diameter(theta: np.ndarray) -> Diameter:
    """max |O_i - O_j|_F of the planar rotations by angles ``theta`` (module docstring)."""
    _, arc = circle_arc(theta)
    if arc < math.pi:
        exact = 2.0 * math.sqrt(2.0) * math.sin(arc / 2.0)
        return Diameter(exact, exact)
    return Diameter(2.0, 2.0 * math.sqrt(2.0))
