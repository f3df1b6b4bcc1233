"""The input contract: bad input -> one line `polymatch: error: KEY.PATH: ...`, exit 2, fast.

Concrete inputs for every class of the contract (test/support/input_cases.py), command-line parse
errors, real subprocesses under an address-space limit, and a property-based test that
mutates valid scenes (test/support/input_fuzz.py; `python test/support/soak_inputs.py` runs it
longer).
"""

import os
import resource
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import pytest
from input_cases import BASE, CASES, PARSE_CASES, bomb, nested, scene
from input_fuzz import Timeout, address_space_limit, contract_violation, fuzz, run_main

from polymatch_ros.core.saved import load_saved

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / "config"


def _refusal(tmp_path, data, args):
    path = tmp_path / "scene.yaml" if data is not None else tmp_path
    if data is not None:
        path.write_bytes(data)
    argv = ["simulate", str(path), "-q"] + args
    if "EXPLAIN" in args:
        argv = ["explain", str(path)] + [a for a in args if a != "EXPLAIN"]
    start = time.process_time()  # CPU: on a loaded machine wall time measures the load
    with address_space_limit(2 * 2**30):
        code, out, err = run_main(argv, 20.0)
    return code, err.replace(str(path), "DIR" if data is None else "SCENE"), \
        time.process_time() - start


@pytest.mark.parametrize("cls,name,data,args,want", CASES,
                         ids=[f"class{c[0]}_{c[1]}" for c in CASES])
def test_bad_input_is_one_line_exit_2_naming_the_key(tmp_path, cls, name, data, args, want):
    code, err, seconds = _refusal(tmp_path, data, args)
    assert code == 2, err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert err.startswith("polymatch: error: " + want), err
    assert seconds < 10


@pytest.mark.parametrize("name,argv,want", PARSE_CASES, ids=[c[0] for c in PARSE_CASES])
def test_command_line_parse_error_is_one_line_with_help_hint(name, argv, want):
    code, out, err = run_main(argv, 20.0)
    assert code == 2
    assert err.count("\n") == 1 and err.startswith("polymatch: error: " + want), err
    assert "--help`)" in err


def test_valid_base_scene_runs_so_the_refusals_are_not_blanket(tmp_path):
    path = tmp_path / "scene.yaml"
    path.write_bytes(BASE)
    code, out, err = run_main(["simulate", str(path), "-q"], 60.0)
    assert contract_violation(code, out, err) is None and code in (0, 3), err
    path.write_bytes(scene("time: {t_end: 1e3}", "integrator: {method: rkmk4, dt: 1e-3}"))
    code, out, err = run_main(["explain", str(path)], 60.0)     # 1e6 steps: within max_steps
    assert code == 0, err


def test_yaml_1_2_exponents_are_numbers_and_shipped_scenes_load():
    from polymatch_ros.core import load_scene
    s = load_scene(scene("integrator: {method: rkmk4, dt: 1e-2}").decode())
    assert s.integrator.dt == 0.01
    scenes = [p for p in sorted(CONFIG.glob("**/*.yaml")) if "params" not in p.parts]
    assert len(scenes) >= 10                # config/params/ holds ROS parameter files
    for path in scenes:
        load_scene(path)


def test_save_without_suffix_reports_the_file_written(tmp_path):
    path = tmp_path / "scene.yaml"
    path.write_bytes(BASE)
    code, out, err = run_main(["simulate", str(path), "-q", "--save", str(tmp_path / "traj")], 60)
    assert code in (0, 3), err
    assert f"trajectory saved to {tmp_path / 'traj.npz'}" in out
    assert load_saved(tmp_path / "traj.npz").t == pytest.approx(2.0)


def test_scene_tolerance_unused_by_auto_pick_warns_one_line(tmp_path):
    path = tmp_path / "scene.yaml"
    path.write_bytes(scene("model: {order: 2, mass: 1e-8, gamma: 2.0}",
                           "integrator: {method: auto, tolerance: 1e-6}"))
    code, out, err = run_main(["explain", str(path)], 60.0)
    assert code == 0
    assert err.startswith("polymatch: warning: integrator.tolerance = 1e-06 is not used: etd2")


def test_writable_output_helper_appends_suffix_and_refuses_missing_directory(tmp_path):
    from polymatch_ros.console import writable_output
    from polymatch_ros.core import ParameterError
    assert writable_output(tmp_path / "x", ".npz") == str(tmp_path / "x.npz")
    assert writable_output(tmp_path / "x.NPZ", ".npz") == str(tmp_path / "x.NPZ")
    with pytest.raises(ParameterError, match="does not exist"):
        writable_output(tmp_path / "missing" / "x.png", ".png")
    with pytest.raises(ParameterError, match="is a directory"):
        writable_output(tmp_path, "")


def test_run_logs_into_a_file_is_one_line_and_exit_2_before_anything_starts(tmp_path):
    afile = tmp_path / "afile"
    afile.write_text("")
    for bad in (afile, afile / "below"):
        code, out, err = run_main(["run", "congruent_triangles", "--logs", str(bad)], 60)
        assert code == 2 and err.startswith("polymatch: error: --logs: cannot make "), err
        assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err


@pytest.mark.parametrize("domain,argv,words", [
    ("abc", [], "ROS_DOMAIN_ID='abc' is not a domain id (an integer 0..232)"),
    ("233", [], "ROS_DOMAIN_ID='233' is not a domain id"),
    ("17", ["--isolated", "--only", "0-3"], "--isolated: a run across hosts (--only) needs"),
])
def test_run_domain_options_are_one_line_and_exit_2_before_anything_starts(monkeypatch, domain,
                                                                          argv, words):
    """The run's domain (the user's ROS_DOMAIN_ID, or --isolated) is checked with the options."""
    monkeypatch.setenv("ROS_DOMAIN_ID", domain)
    code, out, err = run_main(["run", "congruent_triangles", *argv], 60)
    assert code == 2 and err.startswith("polymatch: error: ") and words in err, err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err


def test_echo_timeout_must_be_positive():
    code, out, err = run_main(["echo", "/polymatch/diameter", "--timeout", "0"], 60)
    assert code == 2 and err == "polymatch: error: --timeout must be > 0 s, got 0\n", err


SUBPROCESS_CASES = [
    ("binary", bytes(range(256)) * 64, []),
    ("billion_laughs", bomb(), []),
    ("count_1e9", scene(groups="  - {shape: triangle, count: 1000000000}"), []),
    ("nested_1e5", nested(100_000), []),
    ("file_50mb", BASE + b"#" * (50 * 2**20), []),
    ("hypercube_30", scene("dimension: 30", groups="  - {shape: {hypercube: 30}, count: 2}"), []),
]


def _children_cpu():
    """CPU seconds of this process's ended children (user + system)."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _limit_memory():
    resource.setrlimit(resource.RLIMIT_AS, (1536 * 2**20, 1536 * 2**20))


@pytest.mark.parametrize("name,data,args", SUBPROCESS_CASES, ids=[c[0] for c in SUBPROCESS_CASES])
def test_real_process_refuses_within_seconds_and_1_5_gib(tmp_path, name, data, args):
    path = tmp_path / "scene.yaml"
    path.write_bytes(data)
    before = _children_cpu()
    # the refusal within seconds of the process's CPU time; the wall-clock timeout is a hang
    # guard only (on a loaded machine a process gets a sliver of a core)
    res = subprocess.run([sys.executable, "-m", "polymatch_ros.cli", "simulate", str(path), "-q"]
                         + args, capture_output=True, text=True, timeout=180,
                         preexec_fn=_limit_memory, env={**os.environ, "PYTHONWARNINGS": "ignore"})
    assert res.returncode == 2, res.stderr
    assert res.stderr.count("\n") == 1 and res.stderr.startswith("polymatch: error: "), res.stderr
    assert _children_cpu() - before < 15


def test_harness_bound_is_not_reported_as_an_internal_error(tmp_path):
    """The harness's CPU bound ends a long run as ``Timeout``, past the CLI's catch-all; a
    loaded machine (wall time) does not end it."""
    path = tmp_path / "scene.yaml"
    path.write_bytes(scene("time: {t_end: 1e3}", "integrator: {method: rkmk4, dt: 1e-3}"))
    start = time.process_time()
    with pytest.raises(Timeout) as ended:
        run_main(["simulate", str(path), "-q"], 0.5)
    used = time.process_time() - start
    assert used < 5.0
    if ended.value.clock == "cpu":  # else the wall-clock guard (10 s) came first: a loaded CPU
        assert used >= 0.5, used  # the bound is the CPU time the process measures


@pytest.mark.slow
def test_mutated_scenes_keep_the_contract_property_based():
    """A few hundred mutated scenes (types, magnitudes, nesting, keys, encodings, aliases)."""
    stats = fuzz(300, Counter(), derandomize=True)
    assert sum(stats.values()) >= 300
    assert any(k.startswith("ran") for k in stats)          # mutations do not break everything
    assert sum(v for k, v in stats.items() if k.startswith("refused")) > 100


@pytest.mark.parametrize("argv,want", [
    (["-i", "rk5"], "--integrator: unknown integrator 'rk5'; known: "),
    (["--t-end", "1e300"], "--t-end 1e+300: time.samples.every: "),
    (["--dt", "10", "--t-end", "100"], "--dt: rkmk4 is unstable at dt = 10"),
])
def test_run_names_the_option_before_any_process_starts(argv, want):
    code, out, err = run_main(["run", "congruent_triangles", *argv], 20.0)
    assert code == 2 and err.count("\n") == 1, err
    assert err.startswith("polymatch: error: " + want), err
