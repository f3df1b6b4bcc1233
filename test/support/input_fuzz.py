"""Mutated scene files and the input contract they must satisfy (shared by the test and the soak).

Contract (docs/guide/scenes.md): a scene file given to ``polymatch simulate`` either runs
(exit 0, or 3 with a finite diameter: "did not converge" is a verdict, not a crash) or is
refused with exit 2 and exactly one ``polymatch: error: ...`` line on stderr (warning
lines may precede it) -- never a traceback, an internal error, a hang or unbounded memory.
"""

import contextlib
import copy
import functools
import io
import os
import re
import resource
import signal
import tempfile
import threading
import time
from collections import Counter

import yaml
from hypothesis import HealthCheck, settings
from hypothesis import strategies as st

from polymatch_ros import cli

TRI = [[0.0, 1.0], [-0.8660254037844386, -0.5], [0.8660254037844386, -0.5]]

BASES = [
    {"name": "first", "dimension": 2, "seed": 1, "model": {"order": 1, "kappa": 1.0},
     "integrator": {"method": "rkmk4", "dt": 0.05},
     "time": {"t_end": 1.0, "samples": {"every": 0.5}},
     "convergence": {"tolerance": 1e-6, "expected": False},
     "groups": [{"name": "g", "shape": "triangle", "count": 3, "centroids": {"box": [-1.0, 1.0]},
                 "rotations": "uniform"}]},
    {"name": "second", "dimension": 3, "seed": 2,
     "model": {"order": 2, "mass": 0.5, "gamma": 1.0, "kappa": 1.0},
     "time": {"t_end": 1.0, "samples": {"count": 3}}, "convergence": {"expected": False},
     "groups": [{"name": "t", "shape": "tetrahedron", "count": 3,
                 "scales": {"uniform": [0.5, 1.5]},
                 "velocities": {"centroid": {"normal": 0.1}, "angular": "zero"}}]},
    {"name": "mixed", "dimension": 2, "seed": 3,
     "model": {"order": 1, "kappa_2": 0.5, "L": 2.0}, "integrator": {"method": "auto"},
     "time": {"t_end": 1.0}, "convergence": {"expected": False},
     "groups": [{"name": "a", "shape": {"polygon": 5}, "count": 2},
                {"name": "b", "shape": {"vertices": TRI}, "count": 2,
                 "rotations": {"angles": [0.0, 1.0]}, "centroids": {"points": [[0, 0], [1, 1]]}}]},
    {"name": "explicit", "dimension": 2, "integrator": {"method": "adaptive", "tolerance": 1e-6},
     "time": {"t_end": 1.0}, "convergence": {"expected": False},
     "groups": [{"name": "e", "agents": [{"vertices": TRI},
                                         {"vertices": [[y, -x] for x, y in TRI]}]}]},
]

#: the bases as a scene file gives them (sorted keys, plain lists), each example copies one: a
#: YAML round trip per example (the same dicts) was a third of the property test's time
LOADED_BASES = [yaml.safe_load(yaml.safe_dump(base)) for base in BASES]
#: libyaml's emitter where PyYAML has it: the same text as SafeDumper's (checked on 6,000
#: mutated scenes, both flow styles), several times faster
DUMPER = getattr(yaml, "CSafeDumper", yaml.SafeDumper)

KEYS = ["name", "description", "dimension", "seed", "model", "order", "kappa", "gamma", "mass",
        "kappa_2", "L", "representation", "centroids", "integrator", "method", "dt", "tolerance",
        "max_steps", "time", "t_end", "samples", "every", "count", "convergence", "expected",
        "groups", "shape", "size", "rotations", "scales", "velocities", "agents", "vertices",
        "box", "points", "normal", "at", "within", "angles", "polygon", "simplex", "hypercube",
        "uniform", "log_uniform", "similar", "figure", "snapshots", "edges", "std", "mean"]

magnitudes = st.sampled_from([0, 1, -1, 2, 3, 0.5, 1e-300, 1e-12, 1e-6, 1e6, 1e9, 1e12, 1e15,
                              1e300, -1e300, 2**31, 2**64, 10**400, float("inf"), float("nan"),
                              5e-324, 1.7976931348623157e308])
scalars = st.one_of(magnitudes, st.integers(-10**6, 10**6), st.floats(allow_nan=True),
                    st.booleans(), st.none(), st.sampled_from(["", "2", "1e3", "abc", "auto",
                                                                "triangle", "uniform", "zero",
                                                                "adaptive", "\x00", "é"]))
values = st.recursive(scalars, lambda kids: st.one_of(
    st.lists(kids, max_size=4), st.dictionaries(st.sampled_from(KEYS), kids, max_size=3)),
    max_leaves=12)


def _paths(node, prefix=()):
    """Every key path into a nested dict/list."""
    yield prefix
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _paths(v, prefix + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _paths(v, prefix + (i,))


def _get(node, path):
    for p in path:
        node = node[p]
    return node


def _set(node, path, value, delete=False):
    for p in path[:-1]:
        node = node[p]
    if delete:
        del node[path[-1]]
    else:
        node[path[-1]] = value


@st.composite
def scene_dicts(draw):
    """A valid base scene with 1..3 structural mutations (values, deletions, nesting, keys)."""
    data = copy.deepcopy(draw(st.sampled_from(LOADED_BASES)))
    for _ in range(draw(st.integers(1, 3))):
        paths = [p for p in _paths(data) if p]
        leaves = [p for p in paths if isinstance(_get(data, p), (int, float, str))]
        kind = draw(st.sampled_from(["value", "leaf", "leaf", "leaf", "delete", "wrap", "extra"]))
        path = draw(st.sampled_from(leaves if kind == "leaf" and leaves else paths))
        kind = "magnitude" if kind == "leaf" else kind
        if kind == "value":
            _set(data, path, draw(values))
        elif kind == "magnitude":
            _set(data, path, draw(magnitudes))
        elif kind == "delete" and len(path) > 0:
            _set(data, path, None, delete=True)
        elif kind == "wrap":
            old = data
            for p in path:
                old = old[p]
            wrapped = [old] * draw(st.integers(1, 3)) if draw(st.booleans()) else {"x": old}
            _set(data, path, wrapped)
        else:
            parent = data
            for p in path[:-1]:
                parent = parent[p]
            if isinstance(parent, dict):
                parent[draw(st.sampled_from(KEYS + ["unknown"]))] = draw(values)
    return data


@st.composite
def scene_files(draw):
    """Bytes of a scene file: a mutated dict dumped as YAML, then text and encoding mutations."""
    text = yaml.dump(draw(scene_dicts()), Dumper=DUMPER, default_flow_style=draw(st.booleans()),
                     allow_unicode=True)
    kind = draw(st.sampled_from(["plain"] * 6 + ["duplicate", "truncate", "insert", "deep",
                                                  "alias", "utf16", "latin1", "bytes"]))
    lines = text.splitlines(keepends=True)
    if kind == "duplicate" and lines:
        line = draw(st.sampled_from(lines))
        text = text + line
    elif kind == "truncate":
        text = text[:draw(st.integers(0, len(text)))]
    elif kind == "insert":
        at = draw(st.integers(0, len(text)))
        junk = draw(st.sampled_from(["[", "]", "{", ": ", "- ", "&a ", "*a", "!!python/object ",
                                     "\t", "'", "\n  x: 1\n", "? [1]\n"]))
        text = text[:at] + junk + text[at:]
    elif kind == "deep":
        depth = draw(st.integers(30, 5000))
        text += "deep: " + "[" * depth + "]" * depth + "\n"
    elif kind == "alias":
        fan, levels = draw(st.integers(2, 12)), draw(st.integers(2, 12))
        body = "  l0: &l0 [x]\n" + "".join(
            f"  l{i}: &l{i} [{', '.join([f'*l{i - 1}'] * fan)}]\n" for i in range(1, levels))
        text += "description:\n" + body if draw(st.booleans()) else "extra:\n" + body
    raw = text.encode("utf-8")
    if kind == "utf16":
        raw = text.encode("utf-16")
    elif kind == "latin1":
        raw = (text + "# é\n").encode("latin-1", errors="replace")
    elif kind == "bytes":
        at = draw(st.integers(0, len(raw)))
        raw = raw[:at] + draw(st.binary(min_size=1, max_size=8)) + raw[at:]
    return raw


class Timeout(BaseException):
    """The in-process run took longer than its bound.

    A ``BaseException``, as ``KeyboardInterrupt`` is: the CLI's catch-all (``except
    Exception``, the contract's "internal error" line) must not turn the harness's own bound
    into a verdict on the code under test.  ``clock`` names the bound that ran out: "cpu" or
    "wall" (the hang guard).
    """

    def __init__(self, clock: str) -> None:
        super().__init__(f"the {clock} bound ran out")
        self.clock = clock


# The wall-clock bound is a hang guard only, this many times the CPU bound: on a loaded
# machine (four pytest workers and the ROS tests' processes on two cores) a run gets a
# fraction of a core, so a wall-clock bound measures the load, not the code.
WALL_PER_CPU = 20.0
#: how often the guard looks at the clocks (s)
GUARD_PERIOD = 0.01


def run_main(argv, seconds):
    """(exit code, stdout, stderr) of ``cli.main(argv)`` in-process, bounded by ``seconds`` of
    this process's CPU time (``time.process_time``) and ``WALL_PER_CPU`` times that of wall
    time; either raises ``Timeout`` in this thread.

    A guard thread reads the clocks every ``GUARD_PERIOD`` s and, when a bound ran out, sends
    this thread SIGUSR1, whose handler raises.  Not ``ITIMER_PROF``: the kernel charges it by
    scheduler ticks, and on a loaded machine it once expired well before the process's
    measured CPU time reached its bound; the guard's clock is the one callers measure."""
    out, err = io.StringIO(), io.StringIO()
    expired = []

    def expire(signum, frame):
        raise Timeout(expired[0])

    def guard():
        while not done.wait(GUARD_PERIOD):
            clock = ("cpu" if time.process_time() >= cpu_end
                     else "wall" if time.monotonic() >= wall_end else None)
            if clock is not None:
                expired.append(clock)
                signal.pthread_kill(caller, signal.SIGUSR1)
                return

    caller, done = threading.get_ident(), threading.Event()
    old = signal.signal(signal.SIGUSR1, expire)
    cpu_end = time.process_time() + seconds
    wall_end = time.monotonic() + seconds * WALL_PER_CPU
    watcher = threading.Thread(target=guard, name="run_main guard", daemon=True)
    watcher.start()
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                code = cli.main(argv)
            except SystemExit as exc:
                code = exc.code
    finally:
        done.set()
        watcher.join()
        signal.signal(signal.SIGUSR1, old)
    return code, out.getvalue(), err.getvalue()


@contextlib.contextmanager
def address_space_limit(extra_bytes):
    """RLIMIT_AS = current virtual size + ``extra_bytes`` while the block runs."""
    with open("/proc/self/statm") as fh:
        vsize = int(fh.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
    old = resource.getrlimit(resource.RLIMIT_AS)
    resource.setrlimit(resource.RLIMIT_AS, (vsize + extra_bytes, old[1]))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_AS, old)


def contract_violation(code, out, err):
    """None if (code, stdout, stderr) keeps the contract, else what is wrong."""
    if "Traceback" in err or "Traceback" in out:
        return "traceback"
    lines = [x for x in err.splitlines() if x]
    errors = [x for x in lines if not x.startswith("polymatch: warning: ")]
    if code == 2:
        if len(errors) != 1 or not errors[0].startswith("polymatch: error: "):
            return f"exit 2 without exactly one error line: {errors!r}"
        return None
    if code in (0, 3):
        if errors:
            return f"exit {code} with error lines {errors!r}"
        if re.search(r"\bnan\b", out, re.IGNORECASE):
            return "a NaN in the results"
        return None
    return f"exit code {code}: {errors[:1]!r}"


def _timed(slowest, key, argv, seconds):
    """``run_main(argv, seconds)``, keeping the largest CPU time per ``key`` in ``slowest``."""
    start = time.process_time()
    try:
        return run_main(argv, seconds)
    finally:
        if slowest is not None:
            slowest[key] = max(slowest.get(key, 0.0), time.process_time() - start)


def check_scene_file(raw, stats, seconds=3.0, memory="256M", slowest=None, directory=None):
    """Assert the contract for one scene file's bytes; tally the outcome in ``stats``.

    ``seconds`` bounds each call's CPU time (``run_main``); ``slowest``, a dict, collects the
    largest CPU time of a finished simulation, a refusal and a validation (``explain``).
    The file is written as ``scene.yaml`` in ``directory`` (a run's examples share one; a
    temporary directory of its own if None)."""
    if directory is None:
        with tempfile.TemporaryDirectory() as tmp:
            return check_scene_file(raw, stats, seconds, memory, slowest, tmp)
    path = os.path.join(directory, "scene.yaml")
    with open(path, "wb") as fh:
        fh.write(raw)
    try:
        with address_space_limit(3 * 2**30):
            code, out, err = _timed(slowest, "simulate", ["simulate", path, "-q",
                                                          "--memory-limit", memory], seconds)
    except Timeout:
        # accepted scenes may legitimately run long: validation itself must be quick
        code, out, err = _timed(slowest, "explain after a long run",
                                ["explain", path, "--memory-limit", memory], seconds)
        problem = contract_violation(code, out, err)
        assert problem is None and code == 0, f"slow and then {problem or code}: {err!r}"
        stats["accepted, long run (stopped)"] += 1
        return
    problem = contract_violation(code, out, err)
    assert problem is None, f"{problem}\n--- scene ---\n{raw[:2000]!r}\n--- stderr ---\n{err}"
    if code == 2:
        key = err.strip().splitlines()[-1][len("polymatch: error: "):].split(":")[0]
        stats["refused: " + ("FILE" if key == path else key.split("[")[0])] += 1
    else:
        stats[f"ran, exit {code}"] += 1


FUZZ_SETTINGS = dict(deadline=None, database=None, print_blob=True,
                     suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                            HealthCheck.filter_too_much])


def _writing_into(directory):
    """``check_scene_file`` with every file written into ``directory``."""
    return functools.partial(check_scene_file, directory=directory)


def fuzz(examples, stats=None, derandomize=False, slowest=None):
    """Run the property over ``examples`` mutated scene files; return the outcome tally.

    The files share one directory for the run.  Hypothesis seeds a derandomized run from
    ``prop``'s source text: as it was, it runs the examples CI has always run."""
    from hypothesis import given
    stats = Counter() if stats is None else stats
    run_directory = tempfile.TemporaryDirectory()
    check_scene_file = _writing_into(run_directory.name)   # the name ``prop`` calls

    @settings(max_examples=examples, derandomize=derandomize, **FUZZ_SETTINGS)
    @given(scene_files())
    def prop(raw):
        check_scene_file(raw, stats, slowest=slowest)

    with run_directory:
        prop()
    return stats
