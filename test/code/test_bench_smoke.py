"""`python -m benchmarks`: the family table, the command line, the combined report, and every
family that starts no ROS process run with --quick, its tables' values held to what they
measure against (closed forms, scipy, the naive double sum, brute-force vertex distances); the
families that start ROS processes: test/benchmarks/test_bench_ros_families.py.

Benchmarks report figures; nothing here asserts on timings.
"""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from bench_tables import family_tables, number

import benchmarks
from benchmarks import families, main

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[2]

#: the families, in report order (stated here, not read from the package)
FAMILY_NAMES = ["step", "meanfield", "dop853", "precision", "extremes", "longhorizon",
                "distributed", "packing", "scaling", "sweep", "basins", "graphs", "lossy", "trade",
                "bridge", "realtime", "realtime_scale", "watching", "reductions", "faults",
                "leftovers", "process_start"]
#: the families that start ROS processes (test/benchmarks/test_bench_ros_families.py runs them)
ROS_FAMILIES = {"distributed", "packing", "scaling", "graphs", "lossy", "trade", "bridge",
                "realtime", "realtime_scale", "watching", "faults", "leftovers",
                "process_start"}
NUMERIC_FAMILIES = [name for name in FAMILY_NAMES if name not in ROS_FAMILIES]

# headers every family must print
EXPECTED = {
    "step": ["| model", "| method", "best ms", "median ms", "rkmk4", "lie_euler", "rk4_proj",
             "so3 (exp/Rodrigues, SoA)", "matrix (Cayley", "| d: representation", "N = 1,000",
             "best / previous d", "dimensions interleaved"],
    "meanfield": ["mean field best ms", "naive µs/agent (sample)", "naive total, scaled",
                  "speed-up", "max abs diff"],
    "dop853": ["| solver", "rtol=atol", "A: max err", "B: max err (own steps)", "orth. defect",
               "ours (angle)", "ours (matrix, Cayley)", "scipy DOP853",
               "Cheapest run with max error", "A: ours/scipy", "B: ours/scipy",
               "target max error"],
    "precision": ["| method", "h or tol", "max error", "rhs evals", "orth. defect", "rkmk4",
                  "lie_verlet", "adaptive (ours)", "RK45", "DOP853", "observed order", "Frontier",
                  "cheapest (best wall)"],
    "longhorizon": ["rel. energy drift up to", "growth p", "orth. defect up to", "lie_verlet",
                    "refused (unstable)", "RK45", "DOP853", "adaptive (ours)"],
    "extremes": ["| extreme", "| expectation", "what happened", "pass/fail", "wall s", "m = 1e-8",
                 "gamma = 0", "kappa = 1e4", "centroids ~1e9", "one agent", "expectations over"],
    "reductions": ["| reduction", "full / reduced", "angles (Kuramoto) vs 2x2 matrices",
                   "exact flow (Prop. 2.1)", "O(m/gamma) modelling error"],
    "sweep": ["| solver", "batch (rkmk8)", "scipy DOP853 loop", "max vertex error",
              "Speed-up (scipy loop / batch"],
    "basins": ["| N", "stable q (d = 2)", "d = 3 twisted ends", "| p", "var q", "| eps",
               "Findings (computed from the runs above)"],
}


def test_family_table_is_the_stated_list_in_report_order():
    assert list(benchmarks.FAMILIES) == FAMILY_NAMES
    assert [module.NAME for module in families()] == FAMILY_NAMES
    assert set(EXPECTED) == set(NUMERIC_FAMILIES)


def _column(tables, header, name):
    """The cells of column ``name`` in every table whose header has it."""
    return [row[name] for table in tables if name in table[0] and header in table[0]
            for row in table[1]]


def _meanfield(tables, out):
    """The mean field's rates against the naive double sum sum_k (O_k O_i^T - O_i O_k^T)."""
    diffs = [number(c) for c in _column(tables, "mean field best ms", "max abs diff")]
    assert diffs and max(diffs) < 1e-12, diffs


def _dop853(tables, out):
    """Every solver's error within a hundred times its tolerance of the reference; ours stays on
    SO(d) to round-off (scipy's does not: it integrates the matrix entries)."""
    rows = [row for table in tables if "A: max err (11 times)" in table[0] for row in table[1]]
    assert {row["solver"] for row in rows} >= {"ours (angle)", "scipy DOP853"}, rows
    for row in rows:
        assert number(row["A: max err (11 times)"]) < 100 * number(row["rtol=atol"]), row
        if row["solver"].startswith("ours"):
            assert number(row["orth. defect"]) < 1e-12, row


def _precision(tables, out):
    """Observed orders are the methods' nominal orders (Lie-group methods: 1, 2, 4); the
    Lie-group and projection methods stay on SO(d)."""
    orders = [(row["nominal order"], row["observed order (consecutive h, errors > 100 x floor)"])
              for table in tables if "nominal order" in table[0] for row in table[1]]
    assert len(orders) >= 5, orders
    for nominal, observed in orders:
        assert abs(number(observed) - number(nominal)) < 0.3, (nominal, observed)
    rows = [row for table in tables if {"orth. defect", "max error"} <= set(table[0])
            for row in table[1] if row["method"] not in ("RK45", "DOP853")]
    assert len(rows) >= 10, rows
    for row in rows:
        assert number(row["orth. defect"]) < 1e-12, row


def _extremes(tables, out):
    rows = [row for table in tables if "pass/fail" in table[0] for row in table[1]]
    failed = [(row["extreme"], row["what happened"]) for row in rows if row["pass/fail"] != "pass"]
    assert rows and not failed, failed


def _longhorizon(tables, out):
    """Undamped (gamma = 0): the symplectic lie_verlet's energy stays bounded (Prop. 2.2 i);
    every Lie-group method that ran keeps O_i^T O_i = I to round-off."""
    verdicts = {row["method"]: row["verdict"] for table in tables if "verdict" in table[0]
                for row in table[1]}
    assert verdicts["lie_verlet"] == "bounded", verdicts
    defects = [number(row[name]) for header, rows in tables for name in header
               if name.startswith("orth. defect") for row in rows
               if row[name] != "-" and row["method"] not in ("RK45", "DOP853")]
    assert len(defects) >= 5 and max(defects) < 1e-14, defects


def _sweep(tables, out):
    """The batch and scipy's DOP853 both within 1e-6 of the batch at dt/16, and every ensemble
    matched."""
    errors = [number(c) for c in _column(tables, "ensembles timed", "max vertex error")]
    assert len(errors) == 2 and max(errors) < 1e-6, errors
    matched = re.search(r"(\d+)/(\d+) ensembles matched", out)
    assert matched and matched.group(1) == matched.group(2), out


def _basins(tables, out):
    """A ring with k = N/2 neighbours a side is the complete graph: every ensemble matches."""
    rows = [row for table in tables if {"k/N", "d = 2 matched"} <= set(table[0])
            for row in table[1] if number(row["k/N"]) >= 0.5]
    assert rows, tables
    for row in rows:
        for name in ("d = 2 matched", "d = 3 matched"):
            got, of = row[name].split("/")
            assert got == of, row


def _reductions(tables, out):
    """A reduction that is exact differs from the full model by round-off; the others by what
    their column says they leave (rkmk4's centroid error, O(m/gamma) = 1e-3)."""
    rows = [row for table in tables if "expected difference" in table[0] for row in table[1]]
    assert len(rows) >= 6, rows
    for row in rows:
        diff, expected = number(row["max vertex difference at t_end"]), row["expected difference"]
        limit = 1e-13 if expected == "round-off" else 1e-2 if "m/gamma" in expected else 1e-6
        assert diff < limit, row


def _step(tables, out):
    """Each method's right-hand-side evaluations per step are its stages."""
    stages = {"rkmk4": 4, "lie_euler": 1, "rk4_proj": 4, "lie_heun": 2, "lie_verlet": 1}
    rows = [row for table in tables if "evals/step" in table[0] for row in table[1]]
    assert rows
    for row in rows:
        if row["method"] in stages:
            assert number(row["evals/step"]) == stages[row["method"]], row


VALUES = {"meanfield": _meanfield, "dop853": _dop853, "precision": _precision,
          "extremes": _extremes, "longhorizon": _longhorizon, "sweep": _sweep, "basins": _basins,
          "reductions": _reductions, "step": _step}


@pytest.mark.parametrize("name", NUMERIC_FAMILIES)
def test_family_quick(name, capsys):
    assert main([name, "--quick", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("# ")
    for failure in ("run failed", "Failed runs:"):   # a family reports, never hides, a failure
        assert failure not in out, f"{name}: a run inside the family failed"
    for text in EXPECTED[name]:
        assert text in out, f"{name}: {text!r} missing from the output"
    VALUES[name](family_tables(out), out)


def _benchmarks(*args):
    return subprocess.run([sys.executable, "-m", "benchmarks", *args], capture_output=True,
                          text=True, timeout=120, cwd=ROOT)


def test_module_entry_point_runs_a_family():
    res = _benchmarks("meanfield", "--quick", "--quiet")
    assert res.returncode == 0, res.stderr
    assert res.stdout.startswith("# ") and "mean field best ms" in res.stdout
    assert res.stderr == ""


@pytest.mark.parametrize("args,words", [
    (["nosuch"], ["invalid choice: 'nosuch'"]),
    (["step", "--repeats", "0"], ["--repeats", "must be >= 1"]),
    (["extremes", "--quick", "--only", "nope"], ["unknown extreme 'nope'"]),
    (["all", "--quick", "--only", "nope", "--out", "OUT"], ["unknown benchmark family 'nope'"]),
])
def test_bad_input_is_one_line_exit_2(tmp_path, args, words):
    res = _benchmarks(*[str(tmp_path) if a == "OUT" else a for a in args])
    assert res.returncode == 2
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("benchmarks: error: "), res.stderr
    assert all(w in lines[0] for w in words), lines[0]
    assert "Traceback" not in res.stderr and res.stdout == ""


def test_all_writes_one_report(tmp_path, capsys):
    out_dir = tmp_path / "bench"
    assert main(["all", "--quick", "--quiet", "--only", "meanfield",
                     "--out", str(out_dir)]) == 0
    text = (out_dir / "report.md").read_text(encoding="utf-8")
    assert text.startswith("# polymatch benchmark report")
    assert "mean field best ms" in text
    assert (out_dir / "meanfield.md").is_file()
    pytest.importorskip("matplotlib")
    assert os.path.isfile(out_dir / "meanfield_scaling.png")
    assert "![" in text


def test_all_only_keeps_the_other_families_reports(tmp_path, capsys):
    out_dir = tmp_path / "bench"
    out_dir.mkdir()
    earlier = "# Reductions from an earlier run\n\nkept figure 1.23x\n"
    (out_dir / "reductions.md").write_text(earlier, encoding="utf-8")
    assert main(["all", "--quick", "--quiet", "--only", "meanfield",
                     "--out", str(out_dir)]) == 0
    text = (out_dir / "report.md").read_text(encoding="utf-8")
    assert "mean field best ms" in text                       # the family just run
    # the earlier one, one heading level down
    assert "## Reductions from an earlier run" in text
    assert "kept figure 1.23x" in text
    assert "[reductions](reductions.md)" in text
    assert "[step](step.md)" not in text                      # never run here: not listed


def test_all_rejects_unknown_family(tmp_path, capsys):
    assert main(["all", "--quick", "--only", "nope", "--out", str(tmp_path)]) == 2


# -- lossy: the tables from run records (the runs themselves need namespace hosts) -------------

def _monitor(t, diameter, heard=12):
    from polymatch_ros.ros.wire import RunRecord

    return RunRecord(role="monitor", mode="realtime", t=t, diameter=diameter, agents_heard=heard)


def _agent(rate, late=0, steps=100):
    from polymatch_ros.ros.wire import RunRecord

    return RunRecord(role="agent", mode="lockstep", t=1.0, agents=(0,), finished=True,
                     steps=steps, rounds_per_second=rate, late_ticks=late)


def test_lossy_time_to_tolerance_is_where_the_diameter_stays_under():
    from benchmarks.ros_families.lossy import time_to_tolerance

    series = [_monitor(1.0, 1e-3), _monitor(2.0, 1e-7), _monitor(3.0, 1e-5),
              _monitor(4.0, 1e-7, heard=8), _monitor(5.0, 1e-7), _monitor(6.0, 1e-8)]
    # the dip at t = 2 does not count (it rose again); a report of 8 agents is skipped
    assert time_to_tolerance(series, 12, 1e-6) == 5.0
    assert time_to_tolerance(series[:3], 12, 1e-6) is None
    assert time_to_tolerance([], 12, 1e-6) is None


def test_lossy_realtime_rows():
    from benchmarks.ros_families.lossy import REALTIME_HEADER, RealtimeCell, realtime_row

    cell = RealtimeCell(10, 0.05, 0, [_monitor(1.0, 1e-3), _monitor(20.0, 5e-7)],
                        [_agent(0, late=3), _agent(0, late=1)], dropped=42)
    row = realtime_row(cell, 12, 1e-6, 10.0)
    assert len(row) == len(REALTIME_HEADER)
    assert row == ["10", "0.05", "yes", "20.00", "2.00x", "5.00e-07", "4 of 200", "42"]
    stuck = RealtimeCell(40, 0.2, 3, [_monitor(60.0, 2e-2)], [], dropped=7)
    assert realtime_row(stuck, 12, 1e-6, 10.0)[2:6] == ["no", "not reached", "-", "2.00e-02"]
    failed = realtime_row(RealtimeCell(5, 0.0, 1, failure="exit 1"), 12, 1e-6, 10.0)
    assert failed[2] == "failed: exit 1" and len(failed) == len(REALTIME_HEADER)


def test_lossy_lockstep_rows_compare_with_no_loss():
    from benchmarks.ros_families.lossy import LOCKSTEP_HEADER, LockstepCell, lockstep_rows

    cells = [LockstepCell(0, [_agent(40.0), _agent(60.0)], 1e-16, 0, 30.0),
             LockstepCell(10, [_agent(25.0)], 2e-16, 900, 45.0),
             LockstepCell(20, [], None, 0, 0.0, failure="exit codes [1, 0, 0]")]
    rows = lockstep_rows(cells)
    assert [len(r) for r in rows] == [len(LOCKSTEP_HEADER)] * 3
    assert rows[0][:3] == ["0", "50.0", "1.00"] and rows[1][:5] == ["10", "25.0", "0.50",
                                                                   "2.0e-16", "900"]
    assert rows[2][1] == "failed: exit codes [1, 0, 0]"


def test_lossy_deviation_of_the_centralised_run_itself_is_zero(tmp_path):
    """The deviation reads saved poses as `polymatch run --save` writes them."""
    from dataclasses import replace

    import numpy as np

    from benchmarks.ros_families.lossy import central_deviation
    from polymatch_ros.core.scenes.scene import load_scene, resolve_scene_path
    from polymatch_ros.core.stepping.simulate import choose_numerics, simulate
    from polymatch_ros.ros.supervisor.summary import save_final

    scene = load_scene(resolve_scene_path("congruent_triangles"), {"time.t_end": 0.2})
    method = choose_numerics(scene, None, None, distributed=True).name
    traj = simulate(replace(scene, t_end=0.2), method, scene.integrator.dt, samples=[0.2],
                    metrics=False)
    final, at = traj.final, dict.fromkeys(range(scene.model.n_agents), 0.2)
    save_final(str(tmp_path / "final.npz"), traj.scene, final, at)
    assert central_deviation(scene, tmp_path / "final.npz") < 1e-12
    g0 = final.groups[0]
    moved = replace(final, groups=(replace(g0, x=g0.x + np.array([1e-3, 0.0])),
                                   *final.groups[1:]))
    save_final(str(tmp_path / "moved.npz"), traj.scene, moved, at)
    assert abs(central_deviation(scene, tmp_path / "moved.npz") - 1e-3) < 1e-9
