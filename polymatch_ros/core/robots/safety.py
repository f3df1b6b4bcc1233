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

A robot does not apply its command in continuous time: it is held for at most one command period
T (the robot brakes if no newer one comes), reaches the robot through the actuator's lag, and is
computed against peers' positions as old as their stamps.  So each peer is taken where it may
be when the command acts, ``horizon`` = T + latency ahead (``bounded_peers``): its position at
its stamp and the disc of what it can travel in its age plus the horizon, tau_j.  First order
(no peer velocity is sent) the disc is the robots' speed bound times tau_j; second order the
peer is predicted with the velocity it sent (this robot ``horizon`` ahead with its own), and
the disc is what the pair can close within a horizon that the linear prediction misses,
|v_j - v_i| horizon, plus the drift from the prediction within tau_j under the acceleration
and speed bounds.  A peer older than ``stale`` whose disc reaches this robot's is not filtered
against but waited for: the agent holds its robot (the caller's fallback command).

The quadratic programme min |u - u_model|^2 subject to these is solved by DAQP (a dual
active-set solver: exact on these few-variable problems).  ``SafetyFilter.filter`` says when
the command changed.  Robots held short of their places by one another (the closest admissible
command almost still while the model's is not) sidestep in the plane: the admissible command
closest to the model's turned ``SIDESTEP`` clockwise is taken when it moves the robot more (a
right-hand rule, every robot turning the same way, so that a knot of robots circulates);
a ``DeadlockWatch`` says when the filter has held a robot still while the
model still asks it to move (robots held apart, the formation not reached).
"""

from __future__ import annotations

import ctypes
import math
from dataclasses import dataclass

import numpy as np

from ..errors import SceneError
from ..scenes.checks import Map
from ..scenes.limits import MAX_LENGTH, MAX_RATE

SAFETY_KEYS = ("radius", "alpha")
#: a command moved by less than this (relative to max(1, |u_model|)) is unchanged
UNCHANGED = 1e-9
_INF = 1e30     # DAQP's "no bound"
#: a robot the filter holds (planar) tries its model command turned this far clockwise (rad)
SIDESTEP = math.pi / 3
#: held: the model's command at least MOVING (m/s or m/s^2), the filtered one below SHARE of it
MOVING, SHARE = 1e-2, 0.1


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


@dataclass(frozen=True)
class PeerSight:
    """What an agent knows of its peers when it commands: ``positions`` (k, d) at their stamps,
    ``ages`` (k,) (s from each stamp to the command, on one clock), and the ``velocities``
    (k, d) sent with the positions (second order) or None (first order)."""

    positions: np.ndarray
    ages: np.ndarray
    velocities: np.ndarray | None = None


@dataclass(frozen=True)
class MotionBounds:
    """What the filter assumes of the robots: a command acts ``horizon`` s (one command period
    plus the latency to the robot); their ``speed`` (m/s) and ``accel`` (m/s^2) bounds; a peer
    older than ``stale`` s is waited for, not filtered against."""

    horizon: float
    speed: float
    accel: float = math.inf
    stale: float = 0.5


def bounded_peers(p: np.ndarray, v: np.ndarray | None, sight: PeerSight,
                  bounds: MotionBounds) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(own position, peers' positions, reach (k,)) where the command will act (module doc):
    ``v`` this robot's velocity (second order), None for first order."""
    tau = np.maximum(np.asarray(sight.ages, dtype=float), 0.0) + bounds.horizon
    if v is None or sight.velocities is None:
        return np.asarray(p, float), np.asarray(sight.positions, float), bounds.speed * tau
    peer_v = np.asarray(sight.velocities, dtype=float)
    ahead = sight.positions + peer_v * tau[:, None]
    closing = np.linalg.norm(peer_v - v[None, :], axis=1) * bounds.horizon
    drift = np.minimum(0.5 * bounds.accel * tau ** 2,
                       (bounds.speed + np.linalg.norm(peer_v, axis=1)) * tau)
    return p + v * bounds.horizon, ahead, closing + drift


def stale_nearby(own: np.ndarray, ahead: np.ndarray, reach: np.ndarray, ages: np.ndarray,
                 spec: SafetySpec, bounds: MotionBounds) -> bool:
    """Whether a peer older than ``bounds.stale`` may be within its reach of this robot."""
    old = np.asarray(ages, dtype=float) > bounds.stale
    if not np.any(old):
        return False
    gap = np.linalg.norm(ahead[old] - own[None, :], axis=1)
    return bool(np.any(gap < 2.0 * spec.radius + reach[old] + bounds.speed * bounds.horizon))


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


def is_held(nominal: np.ndarray, filtered: Filtered, moving: float = MOVING,
            share: float = SHARE) -> bool:
    """Whether the filter holds the robot: the model's command at least ``moving``, the
    filtered one changed and below ``share`` of it."""
    want = float(np.linalg.norm(nominal))
    return bool(filtered.changed and want >= moving
                and float(np.linalg.norm(filtered.value)) < share * want)


def sidestep_command(nominal: np.ndarray, p: np.ndarray, peers: np.ndarray, spec: SafetySpec,
                     fallback: np.ndarray, v: np.ndarray | None = None,
                     peer_v: np.ndarray | None = None,
                     reach: np.ndarray | None = None) -> Filtered:
    """``filter_command``, and in the plane, when it holds the robot, the admissible command
    closest to the model's turned ``SIDESTEP`` clockwise if that one moves it more."""
    got = filter_command(nominal, p, peers, spec, fallback, v, peer_v, reach)
    if len(nominal) != 2 or not is_held(nominal, got):
        return got
    c, s = math.cos(SIDESTEP), math.sin(SIDESTEP)
    turned = np.array([[c, s], [-s, c]]) @ np.asarray(nominal, dtype=float)
    other = filter_command(turned, p, peers, spec, fallback, v, peer_v, reach)
    if other.infeasible or np.linalg.norm(other.value) <= np.linalg.norm(got.value):
        return got
    return Filtered(other.value, True, other.active)


class DeadlockWatch:
    """Says when the filter has held a robot for ``hold`` s: every command changed, the model's
    linear command at least ``moving`` (m/s or m/s^2) and the filtered one below ``share`` of it
    (robots held apart while the formation is not reached)."""

    def __init__(self, hold: float = 2.0, moving: float = MOVING, share: float = SHARE) -> None:
        self.hold, self.moving, self.share = hold, moving, share
        self.since: float | None = None
        self.deadlocked = False

    def update(self, t: float, nominal: np.ndarray, filtered: Filtered) -> bool:
        """Take one tick; True when the deadlock state changed."""
        if not is_held(nominal, filtered, self.moving, self.share):
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
