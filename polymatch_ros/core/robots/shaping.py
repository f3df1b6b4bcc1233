"""From the model's command to the one a robot receives: formation, separation, drive.

A bridged agent's state is its robot's measured pose in formation coordinates (``formation``):
x_i = q_i - origin - c_i, q_i the robot's position, or on a differential-drive base the point
``axle_offset`` ahead of its axle (``unicycle``).  Its command is the model's (``command``);
with a scene's ``safety`` (or the agent's ``safety_radius``) the linear part is filtered
against every heard peer's position (``safety``; on a unicycle base the discs around the points
ahead have radius r + ell, which cover the robots' own discs of radius r); on a unicycle base
the filtered velocity of the point ahead becomes (v, omega).  The filter takes every peer ever
heard (a peer dropped from the model's sums after its silence is still somewhere in the room),
each where it may be when the command acts (``safety.bounded_peers``: its stamp's age, one
command period and the latency to the robot, the robots' speed and acceleration bounds); a
peer too old to bound that is near holds the robot (``safety.stale_nearby``).  No ROS here.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace
from typing import Any, Protocol

import numpy as np

from ..errors import ParameterError
from ..model import System
from .robot_commands import (
    Twist,
    model_accelerations,
    model_rates,
    saturate,
    twist_command,
)
from .safety import (
    DeadlockWatch,
    Filtered,
    MotionBounds,
    PeerSight,
    SafetySpec,
    bounded_peers,
    sidestep_command,
    stale_nearby,
)
from .unicycle import point_ahead, unicycle_command

DRIVES = ("holonomic", "unicycle")
#: a speed limit this large is none (the parameters' default)
UNBOUNDED = 1e6


def heading_of(rot: np.ndarray) -> float:
    """The heading (rad) of a 2x2 (or the z-rotation of a 3x3) rotation matrix."""
    return math.atan2(float(rot[1, 0]), float(rot[0, 0]))


class CommandShaper:
    """One bridged agent's measured state and shaped commands (module doc)."""

    def __init__(self, scene: Any, agent: int, drive: str = "holonomic",
                 axle_offset: float = 0.2, safety: SafetySpec | None = None,
                 bounds: MotionBounds | None = None) -> None:
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
        self.safety = spec
        self.bounds = bounds if bounds is not None else MotionBounds(0.1, 1e6)
        self.last_linear = np.zeros(model.dim)   # first order: the command being held
        self.watch = DeadlockWatch()
        self.changed = self.infeasible = self.held = 0

    def offset(self, agent: int) -> np.ndarray | float:
        return 0.0 if self.offsets is None else self.offsets[agent]

    def state_x(self, position: np.ndarray, rot: np.ndarray) -> np.ndarray:
        """The agent's centroid state (formation coordinates) from its robot's measured pose."""
        q = np.asarray(position, dtype=float)
        if self.drive == "unicycle":
            q = point_ahead(q, heading_of(rot), self.ell)
        return q - self.origin - self.offset(self.agent)

    def sight(self, agents: Sequence[int], x: np.ndarray, ages: np.ndarray,
              v: np.ndarray | None = None) -> PeerSight:
        """The peers ``agents`` (this one left out) at their states ``x`` (k, d; formation
        coordinates), ``ages`` (k,) s old, with velocities ``v`` (second order) as the filter
        takes them (world positions relative to the origin)."""
        ids = np.asarray(agents, dtype=int)
        keep = ids != self.agent
        shift = 0.0 if self.offsets is None else self.offsets[ids[keep]]
        dim = self.model.dim
        return PeerSight(np.asarray(x, float).reshape(-1, dim)[keep] + shift,
                         np.asarray(ages, float)[keep],
                         None if v is None else np.asarray(v, float).reshape(-1, dim)[keep])

    def _filter(self, t: float, nominal: np.ndarray, own_x: np.ndarray,
                sight: PeerSight | None, fallback: np.ndarray, v: np.ndarray | None = None,
                own_age: float = 0.0) -> np.ndarray:
        """The filtered linear command (counts changes, infeasible programmes, holds and
        deadlocks); ``own_age`` s since the own pose was measured."""
        if self.safety is None or sight is None or len(sight.ages) == 0:
            return nominal
        moving = self.last_linear if v is None else v
        p = own_x + self.offset(self.agent) + moving * max(own_age, 0.0)
        own, ahead, reach = bounded_peers(p, v, sight, self.bounds)
        if stale_nearby(own, ahead, reach, sight.ages, self.safety, self.bounds):
            got = Filtered(np.asarray(fallback, dtype=float), True, 0)
            self.held += 1
        else:
            got = sidestep_command(nominal, own, ahead, self.safety, fallback, v,
                                   None if v is None else sight.velocities, reach)
        self.changed += got.changed
        self.infeasible += got.infeasible
        self.watch.update(t, nominal, got)
        return got.value

    def command(self, system: System, gi: int, row: int, ensemble: Sequence[Any],
                own: Any, rot: np.ndarray, t: float, p: ShapingOptions,
                sight: PeerSight | None = None, own_age: float = 0.0) -> Twist:
        """The command of local row ``row`` of group gi (first order: a twist; second order: an
        acceleration), ``own`` the measured state (x, rot, v, w) measured ``own_age`` s ago,
        ``rot`` its matrix, ``sight`` the peers for the safety filter (``sight``)."""
        coupling = system.couple(ensemble, first_stage=True)
        x, own_rot = own.x[None], own.rot
        if self.model.order == 2:
            accel, w_dot = model_accelerations(system, gi, x, own_rot, own.v[None], own.w,
                                               coupling)
            brake = -(self.model.gamma / self.model.mass) * own.v
            linear = self._filter(t, accel[0], own.x, sight, brake, own.v, own_age)
            return twist_command(linear, w_dot[0], rot, p.command_frame, p.max_linear_accel,
                                 p.max_angular_accel)
        velocity, skew = model_rates(system, gi, x, own_rot, coupling)
        linear = self._filter(t, velocity[0], own.x, sight, np.zeros_like(velocity[0]),
                              own_age=own_age)
        self.last_linear = linear
        if self.drive == "unicycle":
            return self._unicycle(linear, rot, p.max_linear_speed, p.max_angular_speed)
        return twist_command(linear, skew[0], rot, p.command_frame, p.max_linear_speed,
                             p.max_angular_speed)

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
                "safety_held_for_stale_peers": self.held,
                "safety_deadlock": "yes" if self.watch.deadlocked else "no"}


class ShapingOptions(Protocol):
    """What the shaper takes of a bridged agent's parameters (``ros.config``'s agent table
    gives each, with its default and range; the agent's typed configuration is one)."""

    @property
    def drive(self) -> str: ...

    @property
    def axle_offset(self) -> float: ...

    @property
    def command_frame(self) -> str: ...

    @property
    def rate(self) -> float: ...

    @property
    def safety_radius(self) -> float: ...

    @property
    def safety_alpha(self) -> float: ...

    @property
    def safety_latency(self) -> float: ...

    @property
    def safety_stale(self) -> float: ...

    @property
    def max_linear_speed(self) -> float: ...

    @property
    def max_angular_speed(self) -> float: ...

    @property
    def max_linear_accel(self) -> float: ...

    @property
    def max_angular_accel(self) -> float: ...


def motion_bounds(options: ShapingOptions) -> MotionBounds:
    """What the filter assumes of the robots, from a bridged agent's parameters: a command acts
    one period (``rate``) plus ``safety_latency``; the robots' speed bound ``max_linear_speed``
    (on a unicycle base the point ahead's: hypot(v, axle_offset omega) at the limits), their
    acceleration bound ``max_linear_accel``, and ``safety_stale``."""
    speed = float(options.max_linear_speed)
    if options.drive == "unicycle":
        speed = math.hypot(speed, options.axle_offset * options.max_angular_speed)
    return MotionBounds(1.0 / options.rate + options.safety_latency, speed,
                        float(options.max_linear_accel), float(options.safety_stale))


def shaper_for(scene: Any, agent: int, options: ShapingOptions) -> CommandShaper:
    """The shaper of a bridged agent's parameters: ``drive``, ``axle_offset``, and
    ``safety_radius`` / ``safety_alpha`` (0: the scene's ``safety``, alpha 1 without one), and
    what the filter assumes of the robots (``motion_bounds``)."""
    spec = scene.safety
    radius, alpha = options.safety_radius, options.safety_alpha
    if radius > 0:
        spec = SafetySpec(radius, alpha if alpha > 0 else (spec.alpha if spec else 1.0))
    elif spec is not None and alpha > 0:
        spec = replace(spec, alpha=alpha)
    if spec is not None and not options.max_linear_speed < UNBOUNDED:
        raise ParameterError("the safety filter needs the robots' speed bound: "
                             "max_linear_speed (m/s; polymatch run --max-linear-speed)")
    return CommandShaper(scene, agent, options.drive, options.axle_offset, spec,
                         motion_bounds(options))
