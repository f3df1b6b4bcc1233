"""A rerun only where a ROS world runs: a test gets pytest-rerunfailures' one rerun only if it
takes a ROS world (the ``ros`` fixture, or a ``net`` of namespace hosts: conftest.py's
``ROS_WORLD_FIXTURES``), and every test in test/ros, test/hosts and test/benchmarks takes one, so
a test of pure code that fails once fails the run.  Read from the suite as pytest collects it."""

import configparser
import json
import os
import pathlib
import subprocess
import sys

ROOT = pathlib.Path(__file__).resolve().parents[2]
WORLD_FOLDERS = {"ros", "hosts", "benchmarks"}
WORLD_FIXTURES = {"ros", "net"}

DUMP = '''
import json, os


def pytest_collection_finish(session):
    reruns = session.config.getoption("reruns", None) or 0
    rows = []
    for item in session.items:
        marker = item.get_closest_marker("flaky")
        own = 0
        if marker is not None:
            own = marker.kwargs.get("reruns", marker.args[0] if marker.args else 1)
        rows.append({"id": item.nodeid, "fixtures": sorted(item.fixturenames),
                     "reruns": max(own, reruns)})
    with open(os.environ["RERUN_DUMP"], "w") as fh:
        json.dump(rows, fh)
'''


def _collected(tmp_path):
    (tmp_path / "rerun_dump.py").write_text(DUMP)
    out = tmp_path / "items.json"
    env = {**os.environ, "PYTHONPATH": f"{tmp_path}:{ROOT}", "RERUN_DUMP": str(out)}
    proc = subprocess.run([sys.executable, "-m", "pytest", "--collect-only", "-q", "-n", "0",
                           "-p", "rerun_dump", "-p", "no:cacheprovider", "test"],
                          cwd=ROOT, env=env, capture_output=True, text=True, timeout=300,
                          check=False)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return json.loads(out.read_text())


def test_only_tests_that_start_a_ros_world_get_a_rerun_and_the_world_folders_hold_only_them(
        tmp_path):
    items = _collected(tmp_path)
    assert len(items) > 1000, len(items)
    rerun_without_world, world_folder_without_world, world_elsewhere = [], [], []
    for item in items:
        world = bool(WORLD_FIXTURES & set(item["fixtures"]))
        folder = item["id"].split("/")[1]
        if item["reruns"] and not world:
            rerun_without_world.append(item["id"])
        if folder in WORLD_FOLDERS and not world:
            world_folder_without_world.append(item["id"])
        if world and folder not in WORLD_FOLDERS:
            world_elsewhere.append(item["id"])
    assert rerun_without_world == [], "a rerun without a ROS world: " + " ".join(
        rerun_without_world[:20])
    assert world_folder_without_world == [], (
        "starts no ROS world, belongs in test/core, test/contract or test/code: "
        + " ".join(world_folder_without_world[:20]))
    assert world_elsewhere == [], "a ROS world in the fast part: " + " ".join(world_elsewhere[:20])
    world_tests = [item for item in items if WORLD_FIXTURES & set(item["fixtures"])]
    assert world_tests and all(item["reruns"] == 1 for item in world_tests)


def test_the_summary_names_every_rerun():
    """``-raR``: the run's summary lists each test that failed, and each one rerun."""
    ini = configparser.ConfigParser()
    ini.read(ROOT / "pytest.ini")
    options = ini["pytest"]["addopts"].split()
    assert "-raR" in options
    assert not [o for o in options if o.startswith("--reruns")], options
