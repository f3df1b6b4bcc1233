"""Pose and velocity messages, built and decoded from one table.

``agent_<i>/pose``   d <= 3: ``geometry_msgs/PoseStamped``: position = centroid (z = 0 in 2-D),
                     orientation = quaternion of O_i (about z in 2-D), header.stamp = simulated
                     time, header.frame_id = frame (default ``world``).  d >= 4:
                     ``polymatch_interfaces/msg/PoseNd`` (position, orientation as a row-major
                     d x d matrix).
``agent_<i>/twist``  second order only.  d <= 3: ``geometry_msgs/TwistStamped`` (linear =
                     centroid velocity, angular = spatial angular velocity vee(W_i) of (A-1)).
                     d >= 4: ``polymatch_interfaces/msg/TwistNd`` (linear, angular as the skew
                     d x d matrix W_i).

A decoder checks the contents before the stamp (a corrupt message is named as such) and returns
``(Received, None)`` or ``(None, reason)``, never raises.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from .stage_rows import (
    ROTATION_TOL,
    bad_rotation,
    bad_scalars,
    bad_skew,
    floats,
    header_time,
    shaped,
    stamp_of,
)

if TYPE_CHECKING:
    from ...core.so import RotationGroup

#: (vector, one-row group or algebra array): one agent's state as a decoder returns it
StatePair = tuple[np.ndarray, np.ndarray]


def pose_fields(
    grp: RotationGroup, x: np.ndarray, g: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(position xyz, quaternion xyzw) of one agent for a PoseStamped (d <= 3)."""
    pos = np.zeros(3)
    pos[: len(x)] = x
    if grp.dim == 2:
        if grp.name == "angle":
            theta = float(g[0])
        else:
            mat = grp.to_matrices(g)[0]
            theta = math.atan2(mat[1, 0], mat[0, 0])
        quat = np.array([0.0, 0.0, math.sin(theta / 2), math.cos(theta / 2)])
    else:
        from scipy.spatial.transform import Rotation

        quat = Rotation.from_matrix(grp.to_matrices(g)[0]).as_quat()
    return pos, quat


def twist_fields(
    grp: RotationGroup, v: np.ndarray, w_row: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(linear xyz, angular xyz) of one agent's velocities for a TwistStamped (d <= 3)."""
    lin = np.zeros(3)
    lin[: len(v)] = v
    skew = grp.algebra_to_skew(w_row)[0]
    ang = (
        np.array([skew[2, 1], skew[0, 2], skew[1, 0]])
        if grp.dim == 3
        else np.array([0.0, 0.0, skew[1, 0]])
    )
    return lin, ang


def _stamped(cls: type, t: float, frame_id: str) -> Any:
    msg = cls()
    msg.header.stamp.sec, msg.header.stamp.nanosec = stamp_of(t)
    msg.header.frame_id = frame_id
    return msg


def _numbers(
    vector: Sequence[float], rotation: Sequence[float]
) -> tuple[np.ndarray, np.ndarray, str | None]:
    """A geometry message's two parts as float arrays, and the reason they are unusable."""
    reason = bad_scalars(tuple(vector) + tuple(rotation))
    return np.array(vector, dtype=float), np.array(rotation, dtype=float), reason


def _out_of_plane(vec: np.ndarray, rot: np.ndarray) -> bool:
    """A 2-D message's parts outside the plane: z of the vector, x and y of the rotation."""
    return max(abs(vec[2]), abs(rot[0]), abs(rot[1])) > ROTATION_TOL


def pose_to_state(
    grp: RotationGroup, dim: int, position: Sequence[float], quat: Sequence[float]
) -> tuple[StatePair | None, str | None]:
    """PoseStamped contents -> ((x, one-row rotation), None) or (None, reason)."""
    p, q, reason = _numbers(position, quat)
    if reason:
        return None, reason
    norm = math.hypot(*quat)
    if abs(norm - 1.0) > ROTATION_TOL:
        return None, "quaternion far from unit norm"
    if dim == 2:
        if _out_of_plane(p, q):
            return None, "not a planar pose"
        theta = 2.0 * math.atan2(q[2], q[3])
        mat = np.array([[[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]]])
        return (
            p[:2].copy(),
            grp.from_matrices(mat) if grp.name != "angle" else np.array([theta]),
        ), None
    from scipy.spatial.transform import Rotation

    mat = Rotation.from_quat(q / norm).as_matrix()[None]
    return (p[:3].copy(), grp.from_matrices(mat)), None


def twist_to_state(
    grp: RotationGroup, dim: int, linear: Sequence[float], angular: Sequence[float]
) -> tuple[StatePair | None, str | None]:
    """TwistStamped contents -> ((v, one-row algebra element), None) or (None, reason)."""
    lin, ang, reason = _numbers(linear, angular)
    if reason:
        return None, reason
    if dim == 2:
        if _out_of_plane(lin, ang):
            return None, "not a planar velocity"
        skew = np.array([[[0.0, -ang[2]], [ang[2], 0.0]]])
        return (lin[:2].copy(), grp.algebra_from_skew(skew)), None
    x, y, z = ang
    skew = np.array([[[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]]])
    return (lin[:3].copy(), grp.algebra_from_skew(skew)), None


def nd_to_state(
    msg: Any, spec: _Motion, dim: int, t_max: float | None
) -> tuple[tuple[float, int, np.ndarray, np.ndarray] | None, str | None]:
    """PoseNd / TwistNd -> ((t, key, vector, matrix), None) or (None, reason): the contents
    first (shapes, numbers, SO(d) or skew), then the stamp."""
    rows, reason = shaped({"vec": getattr(msg, spec.parts[0]), "mat": getattr(msg, spec.parts[1])},
                          {"vec": dim, "mat": dim * dim}, 1)
    if rows is None:
        return None, reason
    mat = rows["mat"].reshape(dim, dim)
    reason = bad_rotation(mat) if spec.rotation else bad_skew(mat)
    if reason:
        return None, reason
    stamp, reason = header_time(msg, t_max)
    if stamp is None:
        return None, reason
    return (stamp[0], stamp[1], rows["vec"][0].copy(), mat.copy()), None


@dataclass
class Received:
    """A decoded pose or twist: stamp (s and integer ns key), vector, rotation or algebra row."""

    t: float
    key: int
    vec: np.ndarray
    rot: np.ndarray


def _header_time(
    msg: Any, frame_id: str | None, t_max: float | None
) -> tuple[tuple[float, int] | None, str | None]:
    if frame_id is not None and msg.header.frame_id != frame_id:
        return None, f"unknown frame {msg.header.frame_id!r}"
    return header_time(msg, t_max)


@dataclass(frozen=True)
class _Motion:
    """How one kind of motion message carries an agent's state.

    d <= 3: the geometry message ``cls``, whose field ``body`` holds the parts ``parts`` with
    the components ``axes``; ``fields`` turns (vector, group row) into the parts' values and
    ``to_state`` turns them back.  d >= 4: the message ``nd_cls``, whose fields ``parts`` hold
    the vector and the d x d matrix, made by ``to_matrix`` and read back by ``from_matrix``;
    ``rotation`` says whether the matrix is a rotation (checked in SO(d)) or an angular
    velocity (checked skew).
    """

    cls: str
    body: str
    parts: tuple[str, str]
    axes: tuple[str, str]
    fields: Callable[[RotationGroup, np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]
    to_state: Callable[
        [RotationGroup, int, Sequence[float], Sequence[float]],
        tuple[StatePair | None, str | None],
    ]
    nd_cls: str
    to_matrix: Callable[[RotationGroup, np.ndarray], np.ndarray]
    from_matrix: Callable[[RotationGroup, np.ndarray], np.ndarray]
    rotation: bool


MOTIONS = {
    "pose": _Motion(
        "PoseStamped", "pose", ("position", "orientation"), ("xyz", "xyzw"),
        pose_fields, pose_to_state, "PoseNd",
        lambda grp, one: grp.to_matrices(one)[0], lambda grp, mat: grp.from_matrices(mat),
        rotation=True,
    ),
    "twist": _Motion(
        "TwistStamped", "twist", ("linear", "angular"), ("xyz", "xyz"),
        twist_fields, twist_to_state, "TwistNd",
        lambda grp, w: grp.algebra_to_skew(w)[0], lambda grp, skew: grp.algebra_from_skew(skew),
        rotation=False,
    ),
}


def motion_message(
    kind: str, grp: RotationGroup, t: float, vec: np.ndarray, one: np.ndarray, frame_id: str
) -> Any:
    """One agent's pose or velocity message at simulated time t (type by dimension: see the
    module doc)."""
    spec = MOTIONS[kind]
    if grp.dim >= 4:
        from polymatch_interfaces import msg as own

        msg = _stamped(getattr(own, spec.nd_cls), t, frame_id)
        setattr(msg, spec.parts[0], floats(vec))
        setattr(msg, spec.parts[1], floats(spec.to_matrix(grp, one)))
        return msg
    from geometry_msgs import msg as geometry

    msg = _stamped(getattr(geometry, spec.cls), t, frame_id)
    body = getattr(msg, spec.body)
    for part, axes, values in zip(spec.parts, spec.axes, spec.fields(grp, vec, one)):
        for axis, value in zip(axes, values):
            setattr(getattr(body, part), axis, float(value))
    return msg


def pose_message(
    grp: RotationGroup, t: float, x: np.ndarray, one: np.ndarray, frame_id: str
) -> Any:
    """One agent's pose message (centroid, rotation O_i)."""
    return motion_message("pose", grp, t, x, one, frame_id)


def twist_message(
    grp: RotationGroup, t: float, v: np.ndarray, w_one: np.ndarray, frame_id: str
) -> Any:
    """One agent's velocity message (centroid velocity, spatial angular velocity W_i)."""
    return motion_message("twist", grp, t, v, w_one, frame_id)


def decode_motion(kind: str, msg: Any, grp: RotationGroup, dim: int, frame_id: str | None = None,
                  t_max: float | None = None) -> tuple[Received | None, str | None]:
    """A pose or twist message -> (Received, None) or (None, reason).

    ``frame_id`` (d <= 3): a message in any other frame is refused; ``t_max``: stamps must lie
    in [0, t_max].
    """
    spec = MOTIONS[kind]
    if dim <= 3:
        body = getattr(msg, spec.body)
        parts = [
            tuple(getattr(getattr(body, part), axis) for axis in axes)
            for part, axes in zip(spec.parts, spec.axes)
        ]
        val, reason = spec.to_state(grp, dim, *parts)
        if val is None:                 # the contents first: a corrupt message is named as such
            return None, reason
        stamp, reason = _header_time(msg, frame_id, t_max)
        return (None, reason) if stamp is None else (Received(*stamp, val[0], val[1]), None)
    if frame_id is not None and msg.header.frame_id != frame_id:
        return None, f"unknown frame {msg.header.frame_id!r}"
    res, reason = nd_to_state(msg, spec, dim, t_max)
    if res is None:
        return None, reason
    t, key, vec, mat = res
    return Received(t, key, vec, spec.from_matrix(grp, mat[None])), None


def decode_pose_msg(msg: Any, grp: RotationGroup, dim: int, frame_id: str | None = None,
                    t_max: float | None = None) -> tuple[Received | None, str | None]:
    """PoseStamped (d <= 3) or PoseNd (d >= 4) -> (Received, None) or (None, reason)."""
    return decode_motion("pose", msg, grp, dim, frame_id, t_max)


def decode_twist_msg(msg: Any, grp: RotationGroup, dim: int, frame_id: str | None = None,
                     t_max: float | None = None) -> tuple[Received | None, str | None]:
    """TwistStamped (d <= 3) or TwistNd (d >= 4) -> (Received, None) | (None, reason)."""
    return decode_motion("twist", msg, grp, dim, frame_id, t_max)
