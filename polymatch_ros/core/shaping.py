"""From the model's command to the one a robot receives: formation, separation, drive.

A bridged agent's state is its robot's measured pose in formation coordinates (``formation``):
x_i = q_i - origin - c_i, q_i the robot's position, or on a differential-drive base the point
``axle_offset`` ahead of its axle (``unicycle``).  Its command is the model's (``command``);
with a scene's ``safety`` (or the agent's ``safety_radius``) the linear part is filtered
against every heard peer's position (``safety``; on a unicycle base the discs around the points
ahead have radius r + ell, which cover the robots' own discs of radius r); on a unicycle base
the filtered velocity of the point ahead becomes (v, omega).  The filter looks ``horizon`` s
ahead (one command period plus the latency to the robot) with every peer predicted over the age
of its stamp (``safety.predicted_barrier``): second order with the velocities the peers send,
first order with velocities estimated from their successive stamped positions.  No ROS here.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from .command import (
    Twist,
    model_accelerations,
    model_rates,
    saturate,
    twist_command,
)
from .errors import ParameterError
from .model import System
from .safety import DeadlockWatch, Filtered, SafetySpec, filter_command, predicted_barrier
from .unicycle import point_ahead, unicycle_command

DRIVES = ("holonomic", "unicycle")


def heading_of(rot: np.ndarray) -> float:
    """The heading (rad) of a 2x2 (or the z-rotation of a 3x3) rotation matrix."""
    return math.atan2(float(rot[1, 0]), float(rot[0, 0]))


class CommandShaper:
    """One bridged agent's measured state and shaped commands (module doc)."""

    def __init__(self, scene: Any, agent: int, drive: str = "holonomic",
                 axle_offset: float = 0.2, safety: SafetySpec | None = None,
                 horizon: float = 0.1) -> None:
        model = scene.model
        if drive not in DRIVES:
            raise ParameterError(f"drive {drive!r}: expected holonomic or unicycle")
        if drive == "unicycle" and (model.dim != 2 or model.order != 1):
            raise ParameterError("drive unicycle: a differential-drive base takes first-order "
                                 "commands in 2-D (a scene with dimension 2, model.order 1)")
        if drive == "unicycle" and not axle_offset > 0:
            raise ParameterError(f"axle_offset must be > 0 for drive unicycle, got {axle_offset}")
        self.model, self.origin, self.offsets = model, scene.origin, scene.formation
        self.agent, self.drive, self.ell = agent, drive, axle_offset
        spec = safety if safety is not None else scene.safety
        if spec is not None and drive == "unicycle":
            spec = replace(spec, radius=spec.radius + axle_offset)
        self.safety, self.horizon = spec, horizon
        self.heard: dict[int, tuple[float, np.ndarray]] = {}  # peer -> (stamp, world position)
        self.speeds: dict[int, np.ndarray] = {}  # first order: peer -> estimated velocity
        self.last_linear = np.zeros(model.dim)   # first order: the command being held
        self.watch = DeadlockWatch()
        self.changed = self.infeasible = 0

    def offset(self, agent: int) -> np.ndarray | float:
        return 0.0 if self.offsets is None else self.offsets[agent]

    def state_x(self, position: np.ndarray, rot: np.ndarray) -> np.ndarray:
        """The agent's centroid state (formation coordinates) from its robot's measured pose."""
        q = np.asarray(position, dtype=float)
        if self.drive == "unicycle":
            q = point_ahead(q, heading_of(rot), self.ell)
        return q - self.origin - self.offset(self.agent)

    def peers(self, ensemble: Sequence[Any],
              with_v: bool) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
        """World positions (k, d) (relative to origin), ``with_v`` velocities, and the agent
        numbers (k,) of every heard agent but this one."""
        pos, vel, ids = [], [], []
        for g, e in zip(self.model.groups, ensemble):
            if e is None or e.x is None:
                continue
            rows = np.arange(len(e.x)) if getattr(e, "index", None) is None \
                else np.asarray(e.index)
            agents = g.start + rows
            keep = agents != self.agent
            shift = 0.0 if self.offsets is None else self.offsets[agents[keep]]
            pos.append(e.x[keep] + shift)
            ids.append(agents[keep])
            if with_v:
                vel.append(np.zeros_like(e.x[keep]) if getattr(e, "v", None) is None
                           else e.v[keep])
        empty = np.zeros((0, self.model.dim))
        return (np.concatenate(pos) if pos else empty,
                (np.concatenate(vel) if vel else empty) if with_v else None,
                np.concatenate(ids) if ids else np.zeros(0, dtype=int))

    def _estimated_speeds(self, peers: np.ndarray, ids: np.ndarray,
                          stamps: Mapping[int, float]) -> np.ndarray:
        """First order: each peer's velocity from its last two stamped positions (zero until
        two were heard, or after a gap over 1 s)."""
        out = np.zeros_like(peers)
        for k, agent in enumerate(int(a) for a in ids):
            t = stamps.get(agent)
            if t is None:
                continue
            before = self.heard.get(agent)
            if before is not None and t > before[0]:
                lapse = t - before[0]
                self.speeds[agent] = ((peers[k] - before[1]) / lapse if lapse <= 1.0
                                      else np.zeros_like(peers[k]))
            if before is None or t > before[0]:
                self.heard[agent] = (t, peers[k].copy())
            out[k] = self.speeds.get(agent, 0.0)
        return out

    def _filter(self, t: float, nominal: np.ndarray, own_x: np.ndarray, ensemble: Sequence[Any],
                fallback: np.ndarray, v: np.ndarray | None = None,
                stamps: Mapping[int, float] | None = None) -> np.ndarray:
        """The filtered linear command (counts changes, infeasible programmes, deadlocks);
        ``stamps`` the peers' stamp times (agent -> s, the clock of ``t``), for their ages."""
        if self.safety is None:
            return nominal
        second = v is not None
        peers, peer_v, ids = self.peers(ensemble, second)
        stamps = stamps or {}
        if peer_v is None:
            peer_v = self._estimated_speeds(peers, ids, stamps)
        ages = np.array([t - stamps.get(int(a), t) for a in ids])
        own_v = self.last_linear if v is None else v
        own, ahead, reach = predicted_barrier(own_x + self.offset(self.agent), peers, ages,
                                              self.horizon, own_v, peer_v, own_ahead=second)
        got: Filtered = filter_command(nominal, own, ahead, self.safety, fallback, v,
                                       peer_v if second else None, reach)
        self.changed += got.changed
        self.infeasible += got.infeasible
        self.watch.update(t, nominal, got)
        return got.value

    def command(self, system: System, gi: int, row: int, ensemble: Sequence[Any],
                own: Any, rot: np.ndarray, t: float, p: dict[str, Any],
                stamps: Mapping[int, float] | None = None) -> Twist:
        """The command of local row ``row`` of group gi (first order: a twist; second order: an
        acceleration), ``own`` the measured state (x, rot, v, w), ``rot`` its matrix,
        ``stamps`` the heard peers' stamp times (``_filter``)."""
        coupling = system.couple(ensemble, first_stage=True)
        x, own_rot = own.x[None], own.rot
        if self.model.order == 2:
            accel, w_dot = model_accelerations(system, gi, x, own_rot, own.v[None], own.w,
                                               coupling)
            brake = -(self.model.gamma / self.model.mass) * own.v
            linear = self._filter(t, accel[0], own.x, ensemble, brake, own.v, stamps)
            return twist_command(linear, w_dot[0], rot, p["command_frame"],
                                 p["max_linear_accel"], p["max_angular_accel"])
        velocity, skew = model_rates(system, gi, x, own_rot, coupling)
        linear = self._filter(t, velocity[0], own.x, ensemble, np.zeros_like(velocity[0]),
                              stamps=stamps)
        self.last_linear = linear
        if self.drive == "unicycle":
            return self._unicycle(linear, rot, p["max_linear_speed"], p["max_angular_speed"])
        return twist_command(linear, skew[0], rot, p["command_frame"], p["max_linear_speed"],
                             p["max_angular_speed"])

    def _unicycle(self, velocity: np.ndarray, rot: np.ndarray, max_linear: float,
                  max_angular: float) -> Twist:
        """(v, omega) in the body frame, both scaled by one factor to the limits (the point
        ahead keeps its direction of motion)."""
        v, omega = unicycle_command(velocity, heading_of(rot), self.ell)
        _, cut_v = saturate(np.array([v]), max_linear)
        _, cut_w = saturate(np.array([omega]), max_angular)
        scale = min(1.0, max_linear / abs(v) if v else 1.0, max_angular / abs(omega)
                    if omega else 1.0)
        return Twist(np.array([v * scale, 0.0, 0.0]), np.array([0.0, 0.0, omega * scale]),
                     cut_v or cut_w)

    def note(self) -> dict[str, Any]:
        """Diagnostics: how often the filter changed the command, and whether it deadlocks."""
        if self.safety is None:
            return {}
        return {"safety_changed": self.changed, "safety_infeasible": self.infeasible,
                "safety_deadlock": "yes" if self.watch.deadlocked else "no"}


def shaper_for(scene: Any, agent: int, params: dict[str, Any]) -> CommandShaper:
    """The shaper of a bridged agent's parameters: ``drive``, ``axle_offset``, and
    ``safety_radius`` / ``safety_alpha`` (0: the scene's ``safety``, alpha 1 without one), and
    the filter's horizon: one command period (``rate``) plus ``safety_latency``."""
    spec = scene.safety
    radius, alpha = params.get("safety_radius", 0.0), params.get("safety_alpha", 0.0)
    if radius > 0:
        spec = SafetySpec(radius, alpha if alpha > 0 else (spec.alpha if spec else 1.0))
    elif spec is not None and alpha > 0:
        spec = replace(spec, alpha=alpha)
    return CommandShaper(scene, agent, params.get("drive", "holonomic"),
                         params.get("axle_offset", 0.2), spec,
                         1.0 / params.get("rate", 20.0) + params.get("safety_latency", 0.05))
