"""`polymatch trade --over-ros`: a short real lockstep run gives the round rate, and each
fixed-step setting's wall time per simulated second is its rounds per step / dt / that rate."""

import json

import pytest
from core_testlib import triangles_yaml
from ros_harness import cli_argv, needs_ros

pytestmark = needs_ros

TWO_TRIANGLES = triangles_yaml("two_triangles", seed=2, count=2, method="rkmk4", dt=0.1, t_end=2.0,
                               box=1.0, rotations={"within": 0.3})
# lockstep exchange rounds per step (one per stage), from the methods' tableaux
ROUNDS = {"lie_euler": 1, "lie_heun": 2, "rkmk4": 4, "euler_proj": 1, "rk4_proj": 4}
TARGET = 1e-6


def test_over_ros_wall_per_simulated_second_is_rounds_over_dt_over_measured_rate(ros,
                                                                                tmp_path):
    scene = tmp_path / "two_triangles.yaml"
    scene.write_text(TWO_TRIANGLES)
    # a budget for a loaded machine: the run takes ~6 s alone, and ~46 s beside the suite's
    # other workers, where the lockstep run gets only what the grid leaves of the budget
    proc = ros.start(cli_argv("trade", scene, "--over-ros", "--budget", 120, "--json",
                              "--target-error", TARGET), timeout=210)
    rc = ros.wait(proc, 220)
    text = ros.output(proc)
    assert rc == 0, text
    data = json.loads(text[text.index("{\n"):])
    rate, said = data["ros"], text[:text.index("{\n")]
    # the packing `polymatch run` picks by default: both agents in one process
    assert rate["processes"] == 1 and rate["finished"], (rate, said)
    assert rate["rounds"] >= 200 and rate["rounds_per_second"] > 0
    # the measured rounds cannot have been made faster than the rate says
    assert rate["rounds"] / rate["rounds_per_second"] <= rate["wall"]
    fixed = [r for r in data["rows"] if r["kind"] == "fixed" and r["status"] == "ok"]
    assert {r["solver"] for r in fixed} == set(ROUNDS)
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
