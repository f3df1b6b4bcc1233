"""A minimum separation no command breaks: a control barrier function filter per agent.

Robots are discs of radius r.  For agent i and every peer j it hears,

    h_ij = |p_i - p_j|^2 - (2 r)^2          (>= 0: apart)

and the filter returns the command closest to the model's (least squares) under one linear
constraint per peer.  Each agent takes half of every pair's constraint (the peer, filtering
too, takes the other half; Wang, Ames & Egerstedt, IEEE T-RO 33(3), 2017), so the pair's
constraint holds when both do:

    first order (velocity u_i):        2 (p_i - p_j) . u_i >= -(alpha / 2) h_ij
        (then h' = 2 (p_i - p_j) . (u_i - u_j) >= -alpha h: h decays no faster than e^{-alpha t})
    second order (acceleration a_i):   2 (p_i - p_j) . a_i >= -(2 |v_i - v_j|^2
                                           + 2 alpha h' + alpha^2 h) / 2
        (h'' + 2 alpha h' + alpha^2 h >= 0: the barrier of h' + alpha h, relative degree two)

A robot does not apply its command in continuous time: it is held for one command period T,
reaches the robot through the actuator's lag, and is computed against peers' positions as old as
their stamps.  So the barrier is evaluated where the robots will be when the command acts
(``horizon`` = T + latency ahead): every peer is predicted with its velocity over its age plus
the horizon (second order: the robot's own position too), and each pair's distance 2 r is
widened by ``reach_j`` = |v_j - v_i| horizon, what the pair can close within a horizon that the
linear prediction misses (``predicted_barrier``).

The quadratic programme min |u - u_model|^2 subject to these is solved by DAQP (a dual
active-set solver: exact on these few-variable problems).  ``SafetyFilter.filter`` says when
the command changed, and a ``DeadlockWatch`` when the filter has held a robot still while the
model still asks it to move (robots held apart, the formation not reached).
"""

from __future__ import annotations

import ctypes
import math
from dataclasses import dataclass

import numpy as np

from .checks import Map
from .errors import SceneError
from .limits import MAX_LENGTH, MAX_RATE

SAFETY_KEYS = ("radius", "alpha")
#: a command moved by less than this (relative to max(1, |u_model|)) is unchanged
UNCHANGED = 1e-9
_INF = 1e30     # DAQP's "no bound"


@dataclass(frozen=True)
class SafetySpec:
    """Robots of radius ``radius`` (m) kept 2 r apart; ``alpha`` (1/s) the barrier's rate."""

    radius: float
    alpha: float = 1.0


def parse_safety(raw: object, path: str = "safety") -> SafetySpec:
    """The scene's ``safety: {radius: r, alpha: a}``."""
    sm = Map(raw, path, SAFETY_KEYS)
    if not sm.has("radius"):
        raise SceneError(f"{path}.radius: required (the robots' radius, m)")
    radius = sm.number("radius", positive=True, maximum=MAX_LENGTH)
    alpha = sm.number("alpha", 1.0, positive=True, maximum=MAX_RATE)
    return SafetySpec(float(radius), float(alpha))


@dataclass(frozen=True)
class Filtered:
    """A filtered command: ``value`` (d,), whether it differs from the model's, how many peer
    constraints are active, and ``infeasible`` (no command satisfies them: ``value`` is the
    least violating command, weighted, or the caller's fallback)."""

    value: np.ndarray
    changed: bool
    active: int
    infeasible: bool = False


def barrier_rows(p: np.ndarray, peers: np.ndarray, spec: SafetySpec,
                 v: np.ndarray | None = None, peer_v: np.ndarray | None = None,
                 reach: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(A, b) of the constraints A u >= b of agent at ``p`` against ``peers`` (k, d); with
    velocities ``v`` and ``peer_v`` the second-order ones (module doc); ``reach`` (k,) widens
    each pair's distance 2 r."""
    dp = p[None, :] - peers
    gap = 2.0 * spec.radius + (0.0 if reach is None else np.asarray(reach, dtype=float))
    h = np.einsum("ij,ij->i", dp, dp) - gap ** 2
    a = spec.alpha
    if v is None:
        return 2.0 * dp, -0.5 * a * h
    dv = v[None, :] - (np.zeros_like(peers) if peer_v is None else peer_v)
    h_dot = 2.0 * np.einsum("ij,ij->i", dp, dv)
    return 2.0 * dp, -0.5 * (2.0 * np.einsum("ij,ij->i", dv, dv) + 2.0 * a * h_dot + a * a * h)


def closest_admissible(nominal: np.ndarray, rows: np.ndarray,
                       lower: np.ndarray) -> tuple[np.ndarray | None, int]:
    """argmin |u - nominal|^2 subject to rows u >= lower (DAQP); (None, 0) when infeasible."""
    import daqp

    d = len(nominal)
    if len(rows) == 0 or np.all(rows @ nominal >= lower):
        return nominal.copy(), 0
    x, _, exitflag, _ = daqp.solve(
        np.eye(d), -np.ascontiguousarray(nominal, dtype=float),
        np.ascontiguousarray(rows, dtype=float), np.full(len(rows), _INF),
        np.ascontiguousarray(lower, dtype=float), np.zeros(len(rows), dtype=ctypes.c_int))
    if exitflag < 1:
        return None, 0
    u = np.asarray(x, dtype=float)
    slack = rows @ u - lower
    return u, int(np.sum(slack <= 1e-9 * (1.0 + np.abs(lower))))


def least_violation(nominal: np.ndarray, rows: np.ndarray, lower: np.ndarray,
                    weight: float = 1e4) -> np.ndarray | None:
    """The relaxed programme when no command satisfies every barrier: min |u - nominal|^2 +
    weight |s|^2 subject to rows u + s >= lower, s >= 0 (always feasible; DAQP)."""
    import daqp

    d, k = len(nominal), len(rows)
    cost = np.diag(np.concatenate([np.ones(d), np.full(k, weight)]))
    lin = np.concatenate([-np.asarray(nominal, dtype=float), np.zeros(k)])
    a = np.block([[rows, np.eye(k)], [np.zeros((k, d)), np.eye(k)]])
    lo = np.concatenate([lower, np.zeros(k)])
    x, _, exitflag, _ = daqp.solve(cost, lin, np.ascontiguousarray(a), np.full(2 * k, _INF),
                                   np.ascontiguousarray(lo), np.zeros(2 * k, dtype=ctypes.c_int))
    return None if exitflag < 1 else np.asarray(x[:d], dtype=float)


def predicted_barrier(p: np.ndarray, peers: np.ndarray, ages: np.ndarray, horizon: float,
                      v: np.ndarray, peer_v: np.ndarray,
                      own_ahead: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(own position, peers' positions, reach) where the command will act (module doc): the
    peers ``ages`` (k,) + ``horizon`` s ahead with ``peer_v`` (k, d), this robot ``horizon``
    ahead with ``v`` when ``own_ahead``, and reach_j = |v_j - v| horizon."""
    lead = np.maximum(np.asarray(ages, dtype=float), 0.0) + horizon
    ahead = peers + peer_v * lead[:, None]
    own = p + v * horizon if own_ahead else p
    return own, ahead, np.linalg.norm(peer_v - v[None, :], axis=1) * horizon


def filter_command(nominal: np.ndarray, p: np.ndarray, peers: np.ndarray, spec: SafetySpec,
                   fallback: np.ndarray, v: np.ndarray | None = None,
                   peer_v: np.ndarray | None = None,
                   reach: np.ndarray | None = None) -> Filtered:
    """The command closest to ``nominal`` that keeps every barrier (module doc); ``v`` given:
    an acceleration (second order); ``reach`` (k,) widens the pairs' distances."""
    nominal = np.asarray(nominal, dtype=float)
    if len(peers) == 0 or not np.all(np.isfinite(nominal)):
        return Filtered(nominal, False, 0)
    rows, lower = barrier_rows(np.asarray(p, float), np.asarray(peers, float), spec, v, peer_v,
                               reach)
    u, active = closest_admissible(nominal, rows, lower)
    if u is None:
        relaxed = least_violation(nominal, rows, lower)
        value = np.asarray(fallback, dtype=float) if relaxed is None else relaxed
        return Filtered(value, True, 0, infeasible=True)
    scale = max(1.0, float(np.linalg.norm(nominal)))
    moved = float(np.linalg.norm(u - nominal)) > UNCHANGED * scale
    return Filtered(u if moved else nominal, moved, active)


class DeadlockWatch:
    """Says when the filter has held a robot for ``hold`` s: every command changed, the model's
    linear command at least ``moving`` (m/s or m/s^2) and the filtered one below ``share`` of it
    (robots held apart while the formation is not reached)."""

    def __init__(self, hold: float = 2.0, moving: float = 1e-2, share: float = 0.1) -> None:
        self.hold, self.moving, self.share = hold, moving, share
        self.since: float | None = None
        self.deadlocked = False

    def update(self, t: float, nominal: np.ndarray, filtered: Filtered) -> bool:
        """Take one tick; True when the deadlock state changed."""
        want = float(np.linalg.norm(nominal))
        held = (filtered.changed and want >= self.moving
                and float(np.linalg.norm(filtered.value)) < self.share * want)
        if not held:
            self.since = None
        elif self.since is None:
            self.since = t
        now = self.since is not None and t - self.since >= self.hold
        news = now != self.deadlocked
        self.deadlocked = now
        return news


def min_pair_distance(points: np.ndarray) -> float:
    """The smallest distance between two rows of ``points`` (inf for fewer than two)."""
    if len(points) < 2:
        return math.inf
    diff = points[:, None, :] - points[None, :, :]
    dist = np.sqrt(np.einsum("ijk,ijk->ij", diff, diff))
    dist[np.diag_indices(len(points))] = np.inf
    return float(dist.min())
