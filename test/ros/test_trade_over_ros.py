"""`polymatch trade --over-ros`: a short real lockstep run gives the round rate (its rounds are
the steps times the method's stages, its rate no faster than the test's own clock allows), each
fixed-step setting's error falls with dt at its method's order, and its wall time per simulated
second is its rounds per step / dt / that rate."""

import json
import math
import time

import pytest
from core_testlib import triangles_yaml
from ros_harness import cli_argv, needs_ros

pytestmark = needs_ros

TWO_TRIANGLES = triangles_yaml("two_triangles", seed=2, count=2, method="rkmk4", dt=0.1, t_end=2.0,
                               box=1.0, rotations={"within": 0.3})
# lockstep exchange rounds per step (one per stage), from the methods' tableaux
ROUNDS = {"lie_euler": 1, "lie_heun": 2, "rkmk4": 4, "euler_proj": 1, "rk4_proj": 4}
# their orders (Euler 1, Heun 2, classical Runge-Kutta 4)
ORDERS = {"lie_euler": 1, "lie_heun": 2, "rkmk4": 4, "euler_proj": 1, "rk4_proj": 4}
MEASURED_ROUNDS = 200     # what `trade --over-ros` asks its measuring run for
TARGET = 1e-6


def test_over_ros_wall_per_simulated_second_is_rounds_over_dt_over_measured_rate(ros,
                                                                                tmp_path):
    scene = tmp_path / "two_triangles.yaml"
    scene.write_text(TWO_TRIANGLES)
    # a budget for a loaded machine: the run takes several times longer beside the suite's
    # other workers than alone, where the lockstep run gets only what the grid leaves of the budget
    started = time.monotonic()
    proc = ros.start(cli_argv("trade", scene, "--over-ros", "--budget", 120, "--json",
                              "--target-error", TARGET), timeout=210)
    rc = ros.wait(proc, 220)
    took = time.monotonic() - started
    text = ros.output(proc)
    assert rc == 0, text
    data = json.loads(text[text.index("{\n"):])
    rate, said = data["ros"], text[:text.index("{\n")]
    # the packing `polymatch run` picks by default: both agents in one process
    assert rate["processes"] == 1 and rate["finished"], (rate, said)
    per_step = ROUNDS[rate["method"]]
    steps = math.ceil(MEASURED_ROUNDS / per_step)       # the run's t_end is steps * dt
    assert rate["rounds"] == per_step * steps, (rate, said)
    # the measured rounds cannot have been made faster than the test's own clock allows
    assert rate["rounds"] / rate["rounds_per_second"] <= rate["wall"] <= took, (rate, took)
    fixed = [r for r in data["rows"] if r["kind"] == "fixed" and r["status"] == "ok"]
    assert {r["solver"] for r in fixed} == set(ROUNDS)
    _check_orders(fixed)
    for row in fixed:
        want = ROUNDS[row["solver"]] / row["value"] / rate["rounds_per_second"]
        assert row["ros_wall_per_simulated_second"] == pytest.approx(want, rel=1e-12), row
    # the choice over ROS: the fewest rounds per simulated second that reach the target
    choice = data["choice_over_ros"]
    reaching = [r for r in fixed if r["error"] <= TARGET]
    assert choice["kind"] == "fixed" and choice["error"] <= TARGET
    least = min(ROUNDS[r["solver"]] / r["value"] for r in reaching)
    assert ROUNDS[choice["solver"]] / choice["value"] == pytest.approx(least)
    assert (rate["method"], rate["dt"]) == (choice["solver"], choice["value"])


def _check_orders(fixed):
    """Halving dt divides each method's error by 2^order (within 0.5 of the order), where the
    errors are above round-off."""
    checked = set()
    for coarse in fixed:
        for fine in fixed:
            if (fine["solver"] == coarse["solver"] and fine["value"] * 2 == coarse["value"]
                    and fine["error"] > 1e-11):
                observed = math.log2(coarse["error"] / fine["error"])
                assert abs(observed - ORDERS[coarse["solver"]]) < 0.5, (coarse, fine)
                checked.add(coarse["solver"])
    assert checked, fixed
