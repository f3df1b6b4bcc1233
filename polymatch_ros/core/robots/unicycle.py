"""Differential-drive (unicycle) bases: pose (x, y, theta), commands v (forward) and omega.

A unicycle cannot move sideways, so it cannot follow a model velocity xbar_i' at its axle.
The point q = p + ell (cos theta, sin theta) ahead of the axle can: with

    v     =  cos theta u_x + sin theta u_y
    omega = (-sin theta u_x + cos theta u_y) / ell

q' = u exactly (feedback linearisation of the point ahead; e.g. Siciliano et al., Robotics,
Springer 2009, Sec. 11.6.2).  A bridged agent on a unicycle base takes q as its centroid, so
the centroids of the first-order model (A-2) (and a formation, and the safety filter, on discs
of radius r + ell around q) hold for the points ahead; the heading follows from the motion and
is not the model's: the rotation coupling of (A-2) is not carried out, and the polytopes'
orientations end wherever the robots' headings do.
"""

from __future__ import annotations

import math

import numpy as np


def point_ahead(position: np.ndarray, heading: float, ell: float) -> np.ndarray:
    """q = p + ell (cos theta, sin theta) (2,)."""
    return np.asarray(position, dtype=float)[:2] + ell * np.array([math.cos(heading),
                                                                    math.sin(heading)])


def unicycle_command(velocity: np.ndarray, heading: float, ell: float) -> tuple[float, float]:
    """(v, omega) that move the point ``ell`` ahead of the axle with ``velocity`` (2,)."""
    if not ell > 0:
        raise ValueError(f"the point ahead needs ell > 0, got {ell}")
    c, s = math.cos(heading), math.sin(heading)
    ux, uy = float(velocity[0]), float(velocity[1])
    return c * ux + s * uy, (-s * ux + c * uy) / ell


def unicycle_step(position: np.ndarray, heading: float, v: float, omega: float,
                  dt: float) -> tuple[np.ndarray, float]:
    """The exact unicycle motion over ``dt`` under constant (v, omega): an arc (a line when
    omega = 0)."""
    x, y = float(position[0]), float(position[1])
    turn = omega * dt
    if abs(turn) < 1e-9:
        mid = heading + 0.5 * turn
        return np.array([x + v * dt * math.cos(mid), y + v * dt * math.sin(mid)]), heading + turn
    radius = v / omega
    new = heading + turn
    return (np.array([x + radius * (math.sin(new) - math.sin(heading)),
                      y - radius * (math.cos(new) - math.cos(heading))]), new)


def heading_spread(headings: np.ndarray) -> float:
    """The length of the shortest arc holding every heading (rad, in [0, 2 pi))."""
    t = np.sort(np.mod(np.asarray(headings, dtype=float), 2.0 * math.pi))
    if len(t) < 2:
        return 0.0
    gaps = np.diff(np.concatenate([t, [t[0] + 2.0 * math.pi]]))
    return float(2.0 * math.pi - gaps.max())
