"""Smoke test of `polymatch bench`: every family runs with --quick and prints its tables.

Benchmarks report figures; nothing here asserts on timings.
"""

import os

import pytest

from polymatch_ros import cli
from polymatch_ros.bench import families

# headers the shipped families must print (families added later are only checked for a table)
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
    "distributed": ["| processes", "bare rounds/s best / median", "agents / bare (medians)",
                    "slowest match"],
    "trade": ["| integrator", "rounds/step", "wall s per simulated s", "| rate (Hz)",
              "injected delay"],
    "sweep": ["| solver", "batch (rkmk8)", "scipy DOP853 loop", "max vertex error",
              "Speed-up (scipy loop / batch"],
}

FAMILY_NAMES = [m.NAME for m in families()]


def test_shipped_families_are_registered():
    assert {"step", "meanfield", "dop853", "precision", "longhorizon", "extremes", "reductions",
            "distributed", "trade"} <= set(FAMILY_NAMES)


@pytest.mark.parametrize("name", FAMILY_NAMES)
def test_family_quick(name, capsys):
    assert cli.main(["bench", name, "--quick", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("# ")
    assert "|---" in out                     # at least one markdown table
    for text in EXPECTED.get(name, []):
        assert text in out, f"{name}: {text!r} missing from the output"


def test_all_writes_one_report(tmp_path, capsys):
    out_dir = tmp_path / "bench"
    assert cli.main(["bench", "all", "--quick", "--quiet", "--only", "meanfield",
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
    assert cli.main(["bench", "all", "--quick", "--quiet", "--only", "meanfield",
                     "--out", str(out_dir)]) == 0
    text = (out_dir / "report.md").read_text(encoding="utf-8")
    assert "mean field best ms" in text                       # the family just run
    # the earlier one, one heading level down
    assert "## Reductions from an earlier run" in text
    assert "kept figure 1.23x" in text
    assert "[reductions](reductions.md)" in text
    assert "[step](step.md)" not in text                      # never run here: not listed


def test_all_rejects_unknown_family(tmp_path, capsys):
    assert cli.main(["bench", "all", "--quick", "--only", "nope", "--out", str(tmp_path)]) == 2
