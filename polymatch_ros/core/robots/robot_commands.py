"""Robot commands: velocities for the first-order model (A-2), accelerations for the second-order
model (A-1), and the noise floor.

A robot that tracks its commanded velocity moves as agent i of (A-2):

    xbar_i' = (kappa / gamma N) sum_k (xbar_k - xbar_i)                       (linear)
    O_i'    = W_i O_i,  W_i = kappa/(2 gamma N) (S O_i^T - O_i S^T)            (angular)

``model_rates`` evaluates both with the core's ``System`` (so F-1 weights, F-2 forces and
communication graphs come for free); ``twist_command`` turns them into a twist: linear =
xbar_i', angular = the axial vector of the spatial angular velocity W_i (2-D: only z), in the
world frame or in the robot's body frame (R^T v, R^T omega), each part saturated by norm (the
direction is kept).

A robot that tracks its commanded acceleration (a double integrator) moves as agent i of (A-1):

    m xbar_i'' = -gamma xbar_i' + (kappa / N) sum_k (xbar_k - xbar_i)            (linear)
    O_i' = W_i O_i,  m W_i' = -gamma W_i + kappa/(2N) (S O_i^T - O_i S^T)      (angular)

``model_accelerations`` takes both from the core's ``System.rates`` at the robot's measured
velocities; ``accel_command`` maps them like a twist: linear = xbar_i'', angular = the axial
vector of W_i' (world frame, or R^T of both in the body frame: the body-frame components of
the angular acceleration are exactly R^T omega', those of the linear one are R^T xbar_i'').
``brake_command`` is (A-1) with the coupling off, a = -(gamma/m) v: the damped stop.
No ROS here: the bridge agent and the tests call the same functions.
"""

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..errors import ParameterError
from ..model import Coupling, GroupState, Model, State, System
from ..so.base import Array

FRAMES = ("world", "body")
#: m/s and rad/s: a braking robot slower than this, in both parts, is at rest
STILL = 1e-3


@dataclass(frozen=True)
class Twist:
    """A command: linear and angular (axial vector) velocity or acceleration, 3 components each;
    ``saturated`` when a limit cut it."""

    linear: np.ndarray
    angular: np.ndarray
    saturated: bool = False

    @property
    def finite(self) -> bool:
        return bool(np.all(np.isfinite(self.linear)) and np.all(np.isfinite(self.angular)))


ZERO = Twist(np.zeros(3), np.zeros(3))


def bridge_model(model: Model) -> Model:
    """The model a bridged agent evaluates: centroids by their force (no closed-form flow: a
    robot's centroid is measured, never advanced); refuses what a robot cannot carry out (d >= 4;
    second order without damping)."""
    if model.dim >= 4:
        raise ParameterError(
            f"mode bridge: d = {model.dim}: a twist carries d <= 3 (robots live in 2-D or 3-D)"
        )
    if model.order == 2 and not model.gamma > 0:
        raise ParameterError(
            "mode bridge: a second-order scene needs gamma > 0 (without damping (A-1) never "
            "brings a robot to rest)"
        )
    return replace(model, centroids="integrated")


def model_rates(system: System, gi: int, x: np.ndarray, rot: Array,
                coupling: Coupling) -> tuple[np.ndarray, np.ndarray]:
    """(xbar_i' (n, d), W_i (n, d, d) skew) of the rows ``x``, ``rot`` of group gi (A-2)."""
    model = system.model
    velocity = system.centroid_force(gi, x, coupling) / model.gamma
    rate = system.rotation_rate(gi, rot, coupling)
    return velocity, system.group.algebra_to_skew(rate)


def axial(skew: Any) -> np.ndarray:
    """The axial vector omega of a 2x2 or 3x3 skew matrix (W v = omega x v), 3 components."""
    skew = np.asarray(skew, dtype=float)
    if skew.shape == (2, 2):
        return np.array([0.0, 0.0, skew[1, 0]])
    return np.array([skew[2, 1], skew[0, 2], skew[1, 0]])


def saturate(vec: np.ndarray, limit: float) -> tuple[np.ndarray, bool]:
    """``vec`` scaled down to norm ``limit`` (direction kept); (vector, cut?)."""
    norm = float(np.linalg.norm(vec))
    if norm <= limit or norm == 0.0:
        return vec, False
    return vec * (limit / norm), True


def rotation3(rot: Any) -> np.ndarray:
    """A 2x2 or 3x3 rotation as a 3x3 matrix (2-D: about z)."""
    rot = np.asarray(rot, dtype=float)
    if rot.shape == (3, 3):
        return rot
    out = np.eye(3)
    out[:2, :2] = rot
    return out


def twist_command(velocity: np.ndarray, skew: np.ndarray, rot: np.ndarray, frame: str = "world",
                  max_linear: float = math.inf, max_angular: float = math.inf) -> Twist:
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


def _own_rows(system: System, gi: int, row: int,
              ensemble: Sequence[Any]) -> tuple[Coupling, np.ndarray, Array]:
    """(coupling, x (1, d), rotation (one row)) of local row ``row`` of group gi in
    ``ensemble``."""
    coupling = system.couple(ensemble, first_stage=True)
    index = getattr(ensemble[gi], "index", None)
    k = row if index is None else int(np.flatnonzero(np.asarray(index) == row)[0])
    return coupling, ensemble[gi].x[[k]], system.group.take(ensemble[gi].rot, [k])


def command_from_ensemble(system: System, gi: int, row: int, ensemble: Sequence[Any],
                          rot: np.ndarray, frame: str = "world", max_linear: float = math.inf,
                          max_angular: float = math.inf) -> Twist:
    """The twist of local row ``row`` of group gi against ``ensemble`` (group arrays: every heard
    agent, this one included), ``rot`` its (d, d) orientation."""
    coupling, x, own_rot = _own_rows(system, gi, row, ensemble)
    velocity, skew = model_rates(system, gi, x, own_rot, coupling)
    return twist_command(velocity[0], skew[0], rot, frame, max_linear, max_angular)


def model_accelerations(system: System, gi: int, x: np.ndarray, rot: Array, v: np.ndarray,
                        w: Array, coupling: Coupling) -> tuple[np.ndarray, np.ndarray]:
    """(xbar_i'' (n, d), W_i' (n, d, d) skew) of rows of group gi under (A-1), at velocities
    ``v`` (n, d) and ``w`` (the group's algebra rows of W_i): the core's ``System.rates``."""
    groups: list[GroupState | None] = [None] * len(system.model.groups)
    groups[gi] = GroupState(x, rot, v, w)
    rates = system.rates(State(0.0, tuple(groups)), coupling)[gi]
    assert rates is not None, "the group has rows"
    _, _, accel, w_dot = rates
    return accel, system.group.algebra_to_skew(w_dot)


def accel_command(system: System, gi: int, row: int, ensemble: Sequence[Any], rot: np.ndarray,
                  v: Any, w: Array, frame: str = "world", max_linear: float = math.inf,
                  max_angular: float = math.inf) -> Twist:
    """The acceleration command (A-1) of local row ``row`` of group gi against ``ensemble``:
    ``rot`` its (d, d) orientation, ``v`` (d,) and ``w`` (one algebra row) its measured centroid
    and spatial angular velocity; limits in m/s^2 and rad/s^2."""
    coupling, x, own_rot = _own_rows(system, gi, row, ensemble)
    accel, w_dot = model_accelerations(system, gi, x, own_rot, np.asarray(v)[None], w, coupling)
    return twist_command(accel[0], w_dot[0], rot, frame, max_linear, max_angular)


def brake_command(model: Model, v: Any, skew: Any, rot: np.ndarray, frame: str = "world",
                  max_linear: float = math.inf, max_angular: float = math.inf) -> Twist:
    """The damped stop of a second-order robot: (A-1) with the coupling off, xbar'' =
    -(gamma/m) v and W' = -(gamma/m) W (``skew``); the speed decays as in the model."""
    rate = model.gamma / model.mass
    return twist_command(-rate * np.asarray(v), -rate * np.asarray(skew), rot, frame,
                         max_linear, max_angular)


def is_still(v: Any, skew: Any) -> bool:
    """True when both the speed and the angular speed are below ``STILL``."""
    return float(np.linalg.norm(v)) < STILL and float(np.linalg.norm(axial(skew))) < STILL


def bridge_system(model: Model, rows: Sequence[Any]) -> System:
    """``System`` of the bridged rows ``rows`` (per group) of ``model``."""
    return System(bridge_model(model), rows)


def noise_floor(position_noise: float, angle_noise: float, radius: float, dim: int,
                factor: float = 6.0) -> float:
    """The matching diameter that measurement noise alone produces, with margin ``factor``.

    Two agents' measured vertices differ by the two position errors (sigma_p per coordinate)
    and the two orientation errors times the vertex radius: standard deviation
    sqrt(2) (sigma_p sqrt(d) + sigma_theta r) per pair; ``factor`` covers the maximum over pairs.
    """
    return factor * math.sqrt(2.0) * (position_noise * math.sqrt(dim) + angle_noise * radius)
