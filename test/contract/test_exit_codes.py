"""Exit codes that agree: ``explain`` exits 2 on a scene that ``simulate`` refuses (after
printing what it explains), and ``scenes`` marks the shipped scenes kept to show a refusal.

The oracle is ``simulate`` itself, a separate command run on each shipped scene (with a short
--t-end: a refusal comes before any step, and a runnable scene then runs in moments)."""

import os

import pytest

from polymatch_ros import cli
from polymatch_ros.core.scenes.scene import shipped_config_dirs

CONFIG = shipped_config_dirs()[0]
SCENES = sorted(os.path.join(sub, f[:-5]) if sub else f[:-5]
                for sub in ("", "extremes") for f in os.listdir(os.path.join(CONFIG, sub))
                if f.endswith(".yaml"))


def _simulate_code(name):
    return cli.main(["simulate", name, "--t-end", "0.01", "--quiet"])


@pytest.mark.parametrize("name", SCENES)
def test_explain_exits_as_simulate_does(name, capsys):
    refused = _simulate_code(name) == 2
    capsys.readouterr()
    code = cli.main(["explain", name])
    out, err = capsys.readouterr()
    assert code == (2 if refused else 0)
    assert "scene '" in out and "integrator:" in out          # what it explains, first
    assert ("polymatch: error: " in err) == refused


def test_a_refused_scene_exits_2_from_explain_and_simulate_explain(capsys):
    assert cli.main(["explain", "extremes/scale_ratios"]) == 2
    assert cli.main(["simulate", "extremes/scale_ratios", "--explain"]) == 2
    out, err = capsys.readouterr()
    assert "REFUSED" in out and err.count("polymatch: error: rkmk4 is unstable") == 2


def test_scenes_marks_the_scenes_kept_to_show_a_refusal(capsys):
    refused = set()
    for name in SCENES:
        if _simulate_code(name) == 2:
            refused.add(name)
    capsys.readouterr()
    assert "extremes/scale_ratios" in refused
    assert cli.main(["scenes"]) == 0
    rows = {line.split()[0]: line.split()[4] for line in capsys.readouterr().out.splitlines()
            if line.split() and line.split()[0] in SCENES}
    assert set(rows) == set(SCENES)
    assert {name for name, mark in rows.items() if mark == "refused"} == refused
