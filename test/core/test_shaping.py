"""What a bridged agent sends its robot (core/robots/shaping.py): formation, safety filter, drive.

Oracles: (A-2) written out here for the formation's velocity (kappa/(gamma N) sum_k (y_k - y_i)
with y = q - c); the barrier's half-plane (2 (p_i - p_j) . u >= -(alpha/2) h) checked on the
command sent; the point ahead of the axle moved by the sent (v, omega) over a short arc
(core.robots.unicycle's arc, itself checked against solve_ivp) agrees with the filtered velocity.
"""

import math
from types import SimpleNamespace

import numpy as np
import pytest

from polymatch_ros.core.errors import ParameterError
from polymatch_ros.core.robots.robot_commands import bridge_system
from polymatch_ros.core.robots.safety import MotionBounds
from polymatch_ros.core.robots.shaping import CommandShaper, shaper_for
from polymatch_ros.core.robots.unicycle import point_ahead, unicycle_step
from polymatch_ros.core.scenes.scene import load_scene

#: a bridged agent's shaping options, unbounded (``ShapingOptions``; the tests set what they
#: vary)
UNBOUNDED_OPTIONS = dict(drive="holonomic", axle_offset=0.2, command_frame="world", rate=20.0,
                         safety_radius=0.0, safety_alpha=0.0, safety_latency=0.05,
                         safety_stale=0.5, max_linear_speed=1e6, max_angular_speed=1e6,
                         max_linear_accel=1e6, max_angular_accel=1e6)


def options(**given):
    """Shaping options: ``UNBOUNDED_OPTIONS`` with ``given`` in their place."""
    return SimpleNamespace(**{**UNBOUNDED_OPTIONS, **given})


LIMITS = options()
OFFSETS = [[1.0, 0.0], [-1.0, 0.0], [0.0, 1.5]]


def _scene(**extra):
    return load_scene({"name": "s", "dimension": 2, "model": {"order": 1, "kappa": 2.0},
                       "groups": [{"shape": "triangle", "count": 3,
                                   "centroids": {"points": [[0, 0], [3, 0], [0, 3]]}}],
                       "formation": {"offsets": OFFSETS}, **extra})


def _ensemble(scene, world):
    """Group arrays of heard agents at world centroids ``world`` (formation coordinates)."""
    x = np.asarray(world, float) - scene.origin - np.array(OFFSETS)
    rot = scene.model.rotations.from_matrices(np.tile(np.eye(2), (3, 1, 1)))
    return (SimpleNamespace(x=x, rot=rot, v=None, index=None),), x


def _command(scene, shaper, world, agent=0, ages=(0.0, 0.0, 0.0)):
    """The shaper's command with every agent heard at ``world``, ``ages`` s ago."""
    ensemble, x = _ensemble(scene, world)
    system = bridge_system(scene.model, [np.array([agent])])
    own = SimpleNamespace(x=x[agent], rot=scene.model.rotations.take(ensemble[0].rot, [agent]))
    sight = shaper.sight(range(3), x, np.array(ages))
    return shaper.command(system, 0, agent, ensemble, own, np.eye(2), 0.0, LIMITS, sight)


def test_formation_velocity_is_a2_on_the_offset_centroids():
    scene = _scene()
    world = np.array([[0.3, 0.2], [2.0, -1.0], [0.5, 2.5]])
    y = world - np.array(OFFSETS)
    expected = 2.0 / 3.0 * (y - y[0]).sum(axis=0)       # kappa/(gamma N) sum_k (y_k - y_0)
    twist = _command(scene, CommandShaper(scene, 0), world)
    np.testing.assert_allclose(twist.linear[:2], expected, atol=1e-12)


def test_filtered_command_keeps_the_half_barrier_of_every_peer():
    scene = _scene(safety={"radius": 0.4, "alpha": 1.5})
    world = np.array([[0.0, 0.0], [0.9, 0.0], [0.0, 5.0]])   # agent 1 just outside 2 r = 0.8
    shaper = CommandShaper(scene, 0, bounds=MotionBounds(horizon=0.0, speed=1.0))
    twist = _command(scene, shaper, world)
    u = twist.linear[:2]
    for j in (1, 2):
        dp = world[0] - world[j]
        h = dp @ dp - 0.8 ** 2
        assert 2 * dp @ u >= -0.75 * h - 1e-9
    assert shaper.changed == 1 and shaper.note()["safety_changed"] == 1


def test_peers_heard_late_are_kept_at_the_distance_they_can_close():
    """Agent 1 heard 0.2 s ago, robots at most 0.5 m/s, horizon 0.1 s: the half barrier holds
    for the pair's distance widened to 2 r + 0.5 (0.2 + 0.1) = 2 r + 0.15, written out here;
    a peer heard longer ago than ``stale`` and near holds the robot (zero command, counted)."""
    scene = _scene(safety={"radius": 0.4, "alpha": 1.5})
    world = np.array([[0.0, 0.0], [1.2, 0.0], [0.0, 5.0]])
    shaper = CommandShaper(scene, 0, bounds=MotionBounds(horizon=0.1, speed=0.5, stale=0.5))
    u = _command(scene, shaper, world, ages=(0.0, 0.2, 0.0)).linear[:2]
    for j, gap in ((1, 0.8 + 0.15), (2, 0.8 + 0.05)):
        dp = world[0] - world[j]
        assert 2 * dp @ u >= -0.75 * (dp @ dp - gap ** 2) - 1e-9
    dp = world[0] - world[1]   # the widened barrier binds: the command is slowed to it
    assert abs(2 * dp @ u + 0.75 * (dp @ dp - 0.95 ** 2)) < 1e-9
    world[1, 0] = 1.1      # 0.6 s old: it may be within 2 r + 0.5 (0.6 + 0.1) + 0.5 0.1 = 1.2
    held = _command(scene, shaper, world, ages=(0.0, 0.6, 0.0))
    np.testing.assert_array_equal(held.linear, 0.0)
    assert shaper.note()["safety_held_for_stale_peers"] == 1


def test_unicycle_command_moves_the_point_ahead_with_the_filtered_velocity():
    scene = _scene()
    shaper = shaper_for(scene, 0, options(drive="unicycle", axle_offset=0.25))
    heading = 0.7
    axle = np.array([0.1, -0.2])
    world = np.array([point_ahead(axle, heading, 0.25), [2.0, -1.0], [0.5, 2.5]])
    rot = np.array([[math.cos(heading), -math.sin(heading)], [math.sin(heading),
                                                               math.cos(heading)]])
    x0 = shaper.state_x(axle, rot)
    np.testing.assert_allclose(x0 + scene.origin + OFFSETS[0], world[0], atol=1e-12)
    ensemble, x = _ensemble(scene, world)
    own = SimpleNamespace(x=x0, rot=scene.model.rotations.from_matrices(rot[None]))
    system = bridge_system(scene.model, [np.array([0])])
    twist = shaper.command(system, 0, 0, ensemble, own, rot, 0.0, LIMITS)
    assert twist.linear[1] == 0.0 and twist.angular[0] == twist.angular[1] == 0.0
    h = 1e-8       # forward difference: error ~ h |v| |omega|
    p1, th1 = unicycle_step(axle, heading, twist.linear[0], twist.angular[2], h)
    moved = (point_ahead(p1, th1, 0.25) - world[0]) / h
    expected = _command(scene, CommandShaper(scene, 0), world).linear[:2]
    np.testing.assert_allclose(moved, expected, atol=1e-5)


def test_unicycle_is_refused_for_second_order_scenes():
    scene = load_scene({"name": "s", "dimension": 2, "model": {"order": 2},
                        "groups": [{"shape": "triangle", "count": 2}]})
    with pytest.raises(ParameterError, match="^drive unicycle: "):
        CommandShaper(scene, 0, "unicycle")


def test_safety_without_a_speed_bound_is_refused_in_one_line():
    """The discs of where a peer may be need the robots' speed bound: none given, one line."""
    scene = _scene(safety={"radius": 0.4})
    with pytest.raises(ParameterError, match="^the safety filter needs the robots' speed bound"):
        shaper_for(scene, 0, options())
    shaper = shaper_for(scene, 0, options(max_linear_speed=1.5, rate=20.0, safety_latency=0.1))
    assert shaper.bounds.speed == 1.5 and abs(shaper.bounds.horizon - 0.15) < 1e-15
