"""The suite's layout, markers and shared fixtures.

    test/core/        the numerical core against the paper's claims (no ROS process)
    test/contract/    the input, wire and process contracts: parameters, discovery specs, the
                      runner's recovery and packing, reception times (no ROS process)
    test/code/        the code's own rules: lint, types, layering, sizes, docs; the benchmark
                      tool's numeric families (marker ``slow``)
    test/ros/         ROS worlds: nodes, the runner, multi-process runs      (marker ``ros``)
    test/hosts/       several hosts in network namespaces                    (marker ``hosts``)
    test/benchmarks/  the benchmark families that start ROS processes (--quick)
                                                                   (markers ``ros``, ``slow``)
    test/support/     helpers and the scripts the tests start (not collected)

Markers follow the folders, so ``pytest -m "not ros and not hosts" test`` runs the fast part.
The ``ros`` fixture gives a test its own loopback-only ROS world (support/ros_harness.py), the
``net`` fixtures of test/hosts namespace hosts; every test in test/ros, test/hosts and
test/benchmarks takes one of them, and only those tests get a rerun (test/code/test_reruns.py).
"""

import compileall
import itertools
import os
import pathlib
import re
import sys

import pytest

# One BLAS thread in the test processes and what they start, set before numpy is first imported
# (the xdist workers inherit it): the suite's arrays are small, and on two busy cores scipy's
# threaded OpenBLAS spun in solves of 3x3 systems (``expm``) a hundred times longer than one
# thread takes.
for _threads in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_threads, "1")

HERE = pathlib.Path(__file__).resolve().parent
sys.path.insert(0, str(HERE / "support"))
sys.path.insert(0, str(HERE.parent))        # benchmarks/, beside the package

import shm_account  # noqa: E402
from ros_harness import ROS_SLOTS, ros  # noqa: E402, F401

collect_ignore = ["support"]

# Byte-compiled once, before the workers start: an editable install is never compiled by pip,
# and where PYTHONDONTWRITEBYTECODE is set no process caches what it compiles, so each of the
# suite's ROS processes compiled the package anew, each paying for it in CPU.
COMPILED = ("polymatch_ros", "benchmarks", "test/support")
# The test modules themselves, as pytest rewrites their asserts, are cached the same way: most
# of each worker's collection on the second run (pytest writes them only where this is False).
sys.dont_write_bytecode = False


def pytest_configure(config):
    shm_account.register(config)  # what Fast DDS files the run left in /dev/shm, and when
    if not hasattr(config, "workerinput"):  # the controller, or a run without xdist
        for folder in COMPILED:
            compileall.compile_dir(HERE.parent / folder, quiet=1)


@pytest.hookimpl(optionalhook=True)  # xdist's hook: a run with -p no:xdist has no such hook
def pytest_xdist_auto_num_workers(config):
    """``-n auto`` (pytest.ini): a worker per core, and ``ROS_SLOTS`` more when ROS tests may
    run (they mostly wait on their processes); ``-m "not ros and not hosts"`` gets the cores."""
    cores = len(os.sched_getaffinity(0))
    return cores + (ROS_SLOTS if _may_select(config, ("ros",)) or _may_select(config, ("hosts",))
                    else 0)


def _may_select(config, markers):
    """Whether the ``-m`` expression accepts some test that has ``markers``, whatever other
    markers it has (every assignment of the expression's other names is tried, by pytest's own
    parser of ``-m``; True if unsure)."""
    from _pytest.mark.expression import Expression

    text = config.getoption("markexpr")
    if not text:
        return True
    others = sorted(set(re.findall(r"[A-Za-z_]\w*", text)) - KEYWORDS - set(markers))
    if len(others) > 8:
        return True
    try:
        expression = Expression.compile(text)
    except Exception:  # noqa: BLE001 -- pytest reports a bad -m itself
        return True
    for values in itertools.product((False, True), repeat=len(others)):
        marked = set(markers) | {name for name, on in zip(others, values) if on}
        if expression.evaluate(lambda name, marked=marked, **kwargs: name in marked):
            return True
    return False


KEYWORDS = {"and", "or", "not", "True", "False"}


def pytest_ignore_collect(collection_path, config):
    """Folders whose every test ``-m`` leaves out are not even imported (``FOLDER_MARKERS``)."""
    path = collection_path.resolve()
    if path == HERE or not path.is_relative_to(HERE):
        return None
    markers = FOLDER_MARKERS.get(path.relative_to(HERE).parts[0], ())
    return True if markers and not _may_select(config, markers) else None


FOLDER_MARKERS = {"ros": ("ros",), "hosts": ("hosts",), "benchmarks": ("ros", "slow")}


# Tests that start a ROS world (ROS processes on the wall clock: discovery, round timeouts,
# realtime ticks, robots; on two shared cores) get one rerun (pytest-rerunfailures; ``-raR``
# lists each rerun): a test that fails twice fails the run.  A test of pure code gets none, so
# a flake there fails the run.
ROS_WORLD_FIXTURES = frozenset({"ros", "net"})


def starts_a_ros_world(item) -> bool:
    """Whether a collected test takes a ROS world (``ROS_WORLD_FIXTURES``)."""
    return bool(ROS_WORLD_FIXTURES & set(getattr(item, "fixturenames", ())))


def pytest_collection_modifyitems(config, items):
    """Mark every test by its folder (``FOLDER_MARKERS``); one rerun for a test that starts a
    ROS world (``starts_a_ros_world``)."""
    for item in items:
        folder = pathlib.Path(item.fspath).resolve().relative_to(HERE).parts[0]
        for name in FOLDER_MARKERS.get(folder, ()):
            item.add_marker(getattr(pytest.mark, name))
        if starts_a_ros_world(item):
            item.add_marker(pytest.mark.flaky(reruns=1))


@pytest.hookimpl(wrapper=True, tryfirst=True)
def pytest_runtest_makereport(item, call):
    """Record each phase's report on the item, so fixtures can tell a failed test at teardown."""
    report = yield
    setattr(item, "rep_" + report.when, report)
    return report
