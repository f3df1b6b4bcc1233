"""The safety filter (core/robots/safety.py): a control barrier function per agent.

Oracles: the projection onto one half-plane in closed form; scipy's SLSQP on the same
quadratic programme; the barrier's claim (h_ij >= 0 is forward invariant: no two robots come
closer than 2 r) checked by brute-force distances on robots integrated in the test.
"""

import numpy as np
import pytest
from scipy.optimize import minimize

from polymatch_ros.core.errors import SceneError
from polymatch_ros.core.robots.safety import (
    DeadlockWatch,
    MotionBounds,
    PeerSight,
    SafetySpec,
    barrier_rows,
    bounded_peers,
    filter_command,
    parse_safety,
    sidestep_command,
    stale_nearby,
)

SPEC = SafetySpec(radius=0.5, alpha=2.0)


def test_one_peer_projects_onto_the_half_plane_in_closed_form():
    p, peer = np.array([0.0, 0.0]), np.array([1.5, 0.0])
    nominal = np.array([3.0, 1.0])                 # straight at the peer
    got = filter_command(nominal, p, peer[None], SPEC, np.zeros(2))
    a = 2.0 * (p - peer)
    b = -0.5 * SPEC.alpha * (np.dot(p - peer, p - peer) - 1.0)
    expected = nominal + max(0.0, b - a @ nominal) / (a @ a) * a
    np.testing.assert_allclose(got.value, expected, atol=1e-12)
    assert got.changed and got.active == 1


def test_away_from_peers_the_command_is_the_models():
    got = filter_command(np.array([-1.0, 0.2]), np.zeros(2), np.array([[3.0, 0.0]]), SPEC,
                         np.zeros(2))
    assert not got.changed
    np.testing.assert_array_equal(got.value, [-1.0, 0.2])


@pytest.mark.parametrize("seed", range(20))
def test_many_peers_agree_with_scipy_slsqp(seed):
    rng = np.random.default_rng(seed)
    p = rng.uniform(-2, 2, 2)
    peers = p + rng.uniform(-3, 3, (7, 2))
    peers = peers[np.linalg.norm(peers - p, axis=1) > 1.05]     # every peer outside 2 r
    nominal = rng.normal(0, 2, 2)
    got = filter_command(nominal, p, peers, SPEC, np.zeros(2))
    rows, lower = barrier_rows(p, peers, SPEC)
    ref = minimize(lambda u: np.sum((u - nominal) ** 2), nominal, jac=lambda u: 2 * (u - nominal),
                   constraints=[{"type": "ineq", "fun": lambda u: rows @ u - lower,
                                 "jac": lambda u: rows}],
                   method="SLSQP", options={"ftol": 1e-12, "maxiter": 500})
    assert not got.infeasible and np.all(rows @ ref.x - lower >= -1e-7)
    assert np.all(rows @ got.value - lower >= -1e-9)        # admissible, and no farther than
    assert np.sum((got.value - nominal) ** 2) <= np.sum((ref.x - nominal) ** 2) + 1e-9


def _run(order, filtered, seed, steps=1500, dt=0.01, n=8):
    """8 robots pulled to one point (centroid consensus without offsets: every robot is asked
    to collide); first-order robots take velocities, second-order ones accelerations."""
    rng = np.random.default_rng(seed)
    p = rng.uniform(-4, 4, (n, 2))
    while min(np.linalg.norm(p[i] - p[j]) for i in range(n) for j in range(i)) < 1.2:
        p = rng.uniform(-4, 4, (n, 2))
    v = np.zeros_like(p)
    closest = np.inf
    for _ in range(steps):
        u = np.empty_like(p)
        for i in range(n):
            peers = np.delete(p, i, axis=0)
            if order == 1:
                nominal = p.mean(axis=0) - p[i]
                u[i] = filter_command(nominal, p[i], peers, SPEC, np.zeros(2)).value \
                    if filtered else nominal
            else:
                nominal = -2.0 * v[i] + (p.mean(axis=0) - p[i])
                u[i] = filter_command(nominal, p[i], peers, SPEC, -2.0 * v[i], v[i],
                                      np.delete(v, i, axis=0)).value if filtered else nominal
        if order == 1:
            p = p + dt * u
        else:
            v = v + dt * u
            p = p + dt * v
        d = np.linalg.norm(p[:, None] - p[None], axis=2) + np.eye(n) * 1e9
        closest = min(closest, d.min())
    return closest


@pytest.mark.parametrize("order, n", [(1, 8), (2, 3)])
def test_no_two_filtered_robots_come_closer_than_two_radii(order, n):
    """Forward invariance of h_ij >= 0 (explicit Euler, dt 0.01: to within 1e-3 of 2 r).  Second
    order while every programme is feasible: three robots (eight squeezed into one point can
    leave an agent no admissible acceleration; the benchmark reports what then happens)."""
    for seed in range(2):
        assert _run(order, True, seed, n=n) >= 2 * SPEC.radius * (1 - 1e-3)
        assert _run(order, False, seed, steps=600, n=n) < 2 * SPEC.radius  # the model collides


def test_deadlock_is_reported_after_the_hold_and_cleared_when_the_robot_moves():
    watch = DeadlockWatch(hold=1.0)
    held = filter_command(np.array([1.0, 0.0]), np.zeros(2), np.array([[1.0, 0.0]]), SPEC,
                          np.zeros(2))
    assert held.changed and np.linalg.norm(held.value) < 0.1
    news = [watch.update(t, np.array([1.0, 0.0]), held) for t in np.arange(0.0, 1.6, 0.1)]
    assert watch.deadlocked and news.count(True) == 1
    free = filter_command(np.array([-1.0, 0.0]), np.zeros(2), np.array([[1.0, 0.0]]), SPEC,
                          np.zeros(2))
    assert watch.update(2.0, np.array([-1.0, 0.0]), free) and not watch.deadlocked


def test_safety_key_is_validated_in_one_line():
    assert parse_safety({"radius": 0.3}) == SafetySpec(0.3, 1.0)
    with pytest.raises(SceneError, match=r"^safety\.radius: required"):
        parse_safety({"alpha": 1.0})
    with pytest.raises(SceneError, match=r"^safety\.alpha: "):
        parse_safety({"radius": 0.3, "alpha": -1.0})


def _sampled_loop(bounded, seed, n=8, period=0.05, lag=0.05, age=0.1, t_end=8.0, dt=0.005,
                  stall=0.4):
    """The bridge's loop without ROS: each agent commands at 1/period Hz (its own phase); its
    robot applies a command for one period, then brakes, its velocity following with the lag;
    the agent sees its peers' positions ``age`` s old; every second one agent stalls for
    ``stall`` s (commands nothing: its peers hear nothing newer of it).  Robots pulled to a
    circle formation through one another; the smallest true distance over the run."""
    rng = np.random.default_rng(seed)
    p = rng.uniform(-4, 4, (n, 2))
    while min(np.linalg.norm(p[i] - p[j]) for i in range(n) for j in range(i)) < 0.7:
        p = rng.uniform(-4, 4, (n, 2))
    places = 1.5 * np.stack([np.cos(np.arange(n) * 2 * np.pi / n),
                             np.sin(np.arange(n) * 2 * np.pi / n)], axis=1)
    spec, speed = SafetySpec(radius=0.3, alpha=2.0), 1.0
    bounds = MotionBounds(horizon=period + lag, speed=speed)
    v, cmd, sent = np.zeros_like(p), np.zeros_like(p), np.zeros(n)
    due = rng.uniform(0, period, n)
    stamps, known = np.zeros(n), p.copy()      # what the peers last published, and when
    history = [(0.0, p.copy())]
    closest, t = np.inf, 0.0
    while t < t_end:
        stalled = int(t) % n if t % 1.0 < stall else -1
        seen = max((h for h in history if h[0] <= t - age), key=lambda h: h[0],
                   default=history[0])
        for i in np.flatnonzero(due <= t):
            due[i] += period
            if i == stalled:
                continue
            stamps[i], known[i] = seen[0], seen[1][i]      # i's pose as its peers get it
            peers = np.delete(known, i, axis=0)
            nominal = np.mean(known - places, axis=0) - (p[i] - places[i])
            if bounded:
                sight = PeerSight(peers, t - np.delete(stamps, i))
                own, ahead, reach = bounded_peers(p[i], None, sight, bounds)
                cmd[i] = filter_command(nominal, own, ahead, spec, np.zeros(2),
                                        reach=reach).value
            else:
                cmd[i] = filter_command(nominal, p[i], peers, spec, np.zeros(2)).value
            norm = np.linalg.norm(cmd[i])
            cmd[i] *= min(1.0, speed / norm) if norm > 0 else 1.0
            sent[i] = t
        target = np.where((t - sent <= period)[:, None], cmd, 0.0)   # the robots' watchdog
        v += (dt / lag) * (target - v)
        p = p + dt * v
        t += dt
        history.append((t, p.copy()))
        history = [h for h in history if h[0] >= t - age - 2 * period]
        d = np.linalg.norm(p[:, None] - p[None], axis=2) + np.eye(n) * 1e9
        closest = min(closest, d.min())
    return closest


def test_held_lagged_commands_against_stale_peers_keep_two_radii_with_bounded_peers():
    """The barrier's claim for a sampled loop (commands held one period 0.05 s then braked,
    actuator lag 0.05 s, peers seen 0.1 s late, agents stalling 0.4 s): the plain filter lets
    robots closer than 2 r; with every peer taken as the disc it can reach in its age and the
    horizon (bounded_peers), the brute-force smallest distance stays >= 2 r."""
    plain = [_sampled_loop(False, seed) for seed in (1, 2)]
    assert min(plain) < 2 * 0.3 * 0.97, plain
    bounded = [_sampled_loop(True, seed) for seed in (1, 2)]
    assert min(bounded) >= 2 * 0.3, bounded


def test_bounded_peers_is_the_reachable_disc_in_closed_form():
    """First order: the peer where it was, reach = speed (age + horizon); second order: the
    peer ahead with its velocity over age + horizon, this robot ahead over the horizon, reach =
    |v_j - v_i| horizon + min(accel tau^2 / 2, (speed + |v_j|) tau), written out here."""
    bounds = MotionBounds(horizon=0.1, speed=2.0, accel=3.0)
    sight = PeerSight(np.array([[1.0, 0.0], [0.0, 2.0]]), np.array([0.05, -0.01]),
                      np.array([[0.5, 0.0], [0.0, -1.0]]))
    own, ahead, reach = bounded_peers(np.zeros(2), None, PeerSight(sight.positions, sight.ages),
                                      bounds)
    np.testing.assert_allclose(ahead, sight.positions)
    np.testing.assert_allclose(reach, [2.0 * 0.15, 2.0 * 0.1])
    v = np.array([0.2, 0.0])
    own, ahead, reach = bounded_peers(np.zeros(2), v, sight, bounds)
    np.testing.assert_allclose(own, [0.02, 0.0])
    np.testing.assert_allclose(ahead, [[1.0 + 0.5 * 0.15, 0.0], [0.0, 2.0 - 0.1]])
    tau = np.array([0.15, 0.1])
    drift = np.minimum(1.5 * tau ** 2, (2.0 + np.array([0.5, 1.0])) * tau)
    np.testing.assert_allclose(reach, [0.3 * 0.1, np.hypot(0.2, 1.0) * 0.1] + drift)


def test_a_stale_peer_near_holds_the_robot_and_a_far_one_does_not():
    spec, bounds = SafetySpec(radius=0.3), MotionBounds(horizon=0.1, speed=1.0, stale=0.5)
    near = PeerSight(np.array([[1.5, 0.0]]), np.array([0.8]))
    own, ahead, reach = bounded_peers(np.zeros(2), None, near, bounds)
    assert stale_nearby(own, ahead, reach, near.ages, spec, bounds)  # 1.5 < 0.6 + 0.9 + 0.1
    far = PeerSight(np.array([[1.7, 0.0]]), np.array([0.8]))
    own, ahead, reach = bounded_peers(np.zeros(2), None, far, bounds)
    assert not stale_nearby(own, ahead, reach, far.ages, spec, bounds)
    fresh = PeerSight(np.array([[0.7, 0.0]]), np.array([0.4]))
    own, ahead, reach = bounded_peers(np.zeros(2), None, fresh, bounds)
    assert not stale_nearby(own, ahead, reach, fresh.ages, spec, bounds)


def test_a_held_robot_sidesteps_to_the_projection_of_its_command_turned_clockwise():
    """Two peers ahead, symmetric (gap 2 r = 1 just open, alpha 0.5): the closest admissible
    command is 0.045 m/s forward, under a tenth of the model's 1 m/s (held).  The sidestep
    takes the model's command turned 60 degrees clockwise, (1/2, -sqrt(3)/2), projected onto
    the one half-plane it violates, in closed form, and keeps the other."""
    spec = SafetySpec(radius=0.5, alpha=0.5)
    peers = np.array([[1.0, 0.6], [1.0, -0.6]])
    nominal = np.array([1.0, 0.0])
    plain = filter_command(nominal, np.zeros(2), peers, spec, np.zeros(2))
    np.testing.assert_allclose(plain.value, [0.045, 0.0], atol=1e-12)
    got = sidestep_command(nominal, np.zeros(2), peers, spec, np.zeros(2))
    turned = np.array([0.5, -np.sqrt(3.0) / 2.0])
    a, b = np.array([-2.0, 1.2]), -0.25 * (1.0 + 0.36 - 1.0)       # -(alpha/2) h
    expected = turned + (b - a @ turned) / (a @ a) * a
    np.testing.assert_allclose(got.value, expected, atol=1e-12)
    assert got.changed and np.array([-2.0, -1.2]) @ got.value >= b - 1e-12
