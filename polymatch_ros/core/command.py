"""Velocity commands for robots that follow the first-order model (A-2), and the noise floor.

A robot that tracks its commanded velocity moves as agent i of (A-2):

    xbar_i' = (kappa / gamma N) sum_k (xbar_k - xbar_i)                       (linear)
    O_i'    = W_i O_i,  W_i = kappa/(2 gamma N) (S O_i^T - O_i S^T)            (angular)

``model_rates`` evaluates both with the core's ``System`` (so F-1 weights, F-2 forces and
communication graphs come for free); ``twist_command`` turns them into a twist: linear =
xbar_i', angular = the axial vector of the spatial angular velocity W_i (2-D: only z), in the
world frame or in the robot's body frame (R^T v, R^T omega), each part saturated by norm (the
direction is kept).  No ROS here: the bridge agent and the tests call the same functions.
"""

import math
from dataclasses import dataclass, replace

import numpy as np

from .errors import ParameterError
from .model import System

FRAMES = ("world", "body")


@dataclass(frozen=True)
class Twist:
    """A command: linear and angular (axial vector) velocity, 3 components each; ``saturated``
    when a speed limit cut it."""

    linear: np.ndarray
    angular: np.ndarray
    saturated: bool = False

    @property
    def finite(self):
        return bool(np.all(np.isfinite(self.linear)) and np.all(np.isfinite(self.angular)))


ZERO = Twist(np.zeros(3), np.zeros(3))


def bridge_model(model):
    """The model a bridged agent evaluates: first order, centroids by their force (no closed-form
    flow: a robot's centroid is measured, never advanced); refuses what a twist cannot carry."""
    if model.dim >= 4:
        raise ParameterError(
            f"mode bridge: d = {model.dim}: a twist carries d <= 3 (robots live in 2-D or 3-D)"
        )
    if model.order != 1:
        raise ParameterError(
            "mode bridge: second-order scenes need acceleration commands; use a first-order "
            "scene (A-2: mass 0)"
        )
    return replace(model, centroids="integrated")


def model_rates(system, gi, x, rot, coupling):
    """(xbar_i' (n, d), W_i (n, d, d) skew) of the rows ``x``, ``rot`` of group gi (A-2)."""
    model = system.model
    velocity = system.centroid_force(gi, x, coupling) / model.gamma
    rate = system.rotation_rate(gi, rot, coupling)
    return velocity, system.group.algebra_to_skew(rate)


def axial(skew):
    """The axial vector omega of a 2x2 or 3x3 skew matrix (W v = omega x v), 3 components."""
    skew = np.asarray(skew, dtype=float)
    if skew.shape == (2, 2):
        return np.array([0.0, 0.0, skew[1, 0]])
    return np.array([skew[2, 1], skew[0, 2], skew[1, 0]])


def saturate(vec, limit):
    """``vec`` scaled down to norm ``limit`` (direction kept); (vector, cut?)."""
    norm = float(np.linalg.norm(vec))
    if norm <= limit or norm == 0.0:
        return vec, False
    return vec * (limit / norm), True


def rotation3(rot):
    """A 2x2 or 3x3 rotation as a 3x3 matrix (2-D: about z)."""
    rot = np.asarray(rot, dtype=float)
    if rot.shape == (3, 3):
        return rot
    out = np.eye(3)
    out[:2, :2] = rot
    return out


def twist_command(velocity, skew, rot, frame="world", max_linear=math.inf, max_angular=math.inf):
    """The twist of one agent from its model rates (``velocity`` (d,), ``skew`` W_i (d, d)) at
    orientation ``rot`` (d, d); ``frame``: world or body (components in the robot's frame)."""
    if frame not in FRAMES:
        raise ParameterError(f"frame {frame!r}: expected world or body")
    linear = np.zeros(3)
    linear[: len(velocity)] = velocity
    angular = axial(skew)
    if frame == "body":
        r3 = rotation3(rot)
        linear, angular = r3.T @ linear, r3.T @ angular
    linear, cut_linear = saturate(linear, max_linear)
    angular, cut_angular = saturate(angular, max_angular)
    return Twist(linear, angular, cut_linear or cut_angular)


def command_from_ensemble(system, gi, row, ensemble, rot, frame="world", max_linear=math.inf,
                          max_angular=math.inf):
    """The twist of local row ``row`` of group gi against ``ensemble`` (group arrays: every heard
    agent, this one included), ``rot`` its (d, d) orientation."""
    coupling = system.couple(ensemble, first_stage=True)
    gs_x = ensemble[gi].x
    index = getattr(ensemble[gi], "index", None)
    k = row if index is None else int(np.flatnonzero(np.asarray(index) == row)[0])
    grp = system.group
    velocity, skew = model_rates(system, gi, gs_x[[k]], grp.take(ensemble[gi].rot, [k]), coupling)
    return twist_command(velocity[0], skew[0], rot, frame, max_linear, max_angular)


def bridge_system(model, rows):
    """``System`` of the bridged rows ``rows`` (per group) of ``model``."""
    return System(bridge_model(model), rows)


def noise_floor(position_noise, angle_noise, radius, dim, factor=6.0):
    """The matching diameter that measurement noise alone produces, with margin ``factor``.

    Two agents' measured vertices differ by the two position errors (sigma_p per coordinate)
    and the two orientation errors times the vertex radius: standard deviation
    sqrt(2) (sigma_p sqrt(d) + sigma_theta r) per pair; ``factor`` covers the maximum over pairs.
    """
    return factor * math.sqrt(2.0) * (position_noise * math.sqrt(dim) + angle_noise * radius)
