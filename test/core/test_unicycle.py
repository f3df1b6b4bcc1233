"""Differential-drive bases (core/robots/unicycle.py).

Claims: the point ell ahead of the axle moves with the commanded velocity (feedback
linearisation): checked by differentiating q = p + ell (cos theta, sin theta) numerically
along the unicycle's own motion; the exact arc step against scipy's solve_ivp of
x' = v cos theta, y' = v sin theta, theta' = omega; the first-order centroid consensus
(Prop. 2.1) of the points ahead of 6 unicycles against its closed form.
"""

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from polymatch_ros.core.robots.unicycle import (
    heading_spread,
    point_ahead,
    unicycle_command,
    unicycle_step,
)


@pytest.mark.parametrize("heading", [0.0, 1.0, -2.5])
def test_the_point_ahead_moves_with_the_commanded_velocity(heading):
    p, ell, u = np.array([0.3, -1.0]), 0.2, np.array([0.7, -0.4])
    v, omega = unicycle_command(u, heading, ell)
    h = 1e-6
    q0 = point_ahead(p, heading, ell)
    p1, th1 = unicycle_step(p, heading, v, omega, h)
    np.testing.assert_allclose((point_ahead(p1, th1, ell) - q0) / h, u, atol=1e-5)


@pytest.mark.parametrize("v, omega", [(1.0, 0.0), (0.8, 1.3), (-0.5, -2.0)])
def test_the_arc_step_is_the_unicycle_flow(v, omega):
    def rhs(_, s):
        return [v * math.cos(s[2]), v * math.sin(s[2]), omega]
    ref = solve_ivp(rhs, (0.0, 0.7), [0.1, 0.2, 0.4], rtol=1e-12, atol=1e-12).y[:, -1]
    p, th = unicycle_step(np.array([0.1, 0.2]), 0.4, v, omega, 0.7)
    np.testing.assert_allclose([*p, th], ref, atol=1e-9)


def test_points_ahead_of_unicycles_follow_the_closed_form_consensus():
    rng = np.random.default_rng(4)
    n, ell, rate, dt = 6, 0.15, 1.0, 1e-3
    pos, heading = rng.uniform(-2, 2, (n, 2)), rng.uniform(-math.pi, math.pi, n)
    q0 = np.array([point_ahead(pos[i], heading[i], ell) for i in range(n)])
    mean = q0.mean(axis=0)
    for _ in range(2000):                                  # t = 2
        q = np.array([point_ahead(pos[i], heading[i], ell) for i in range(n)])
        for i in range(n):
            v, omega = unicycle_command(rate * (q.mean(axis=0) - q[i]), heading[i], ell)
            pos[i], heading[i] = unicycle_step(pos[i], heading[i], v, omega, dt)
    q = np.array([point_ahead(pos[i], heading[i], ell) for i in range(n)])
    np.testing.assert_allclose(q, mean + math.exp(-2.0) * (q0 - mean), atol=2e-3)


def test_heading_spread_is_the_shortest_arc():
    # 6.2 rad lies between -0.1 (= 2 pi - 0.1) and 0.1 on the circle: the arc is 0.2
    assert heading_spread(np.array([0.1, -0.1, 6.2])) == pytest.approx(0.2)
    assert heading_spread(np.array([0.0, math.pi / 2, math.pi])) == pytest.approx(math.pi)


def test_a_point_on_the_axle_is_refused():
    with pytest.raises(ValueError, match="ell > 0"):
        unicycle_command(np.array([1.0, 0.0]), 0.0, 0.0)
