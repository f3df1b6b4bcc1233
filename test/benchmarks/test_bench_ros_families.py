"""The benchmark families that start ROS processes run with --quick in the test's ROS world
(its slot of the machine's ROS worlds) and print their tables, the values held to what they
count (processes x agents = agents, rounds per step = the integrator's stages, every run
finished, the robots' true diameter below the noise floor).

lossy runs ROS ensembles on namespace hosts: even --quick takes about a minute, and its tables
are tested from records (test/code/test_bench_smoke.py); faults --quick takes two minutes of
killing and restarting processes, and what it measures is asserted in test/ros/test_faults.py.
"""

import math
import re
import statistics

import pytest
from bench_tables import family_tables, number

from benchmarks import main

ROS_QUICK_FAMILIES = ["distributed", "packing", "scaling", "graphs", "trade", "bridge",
                      "realtime", "realtime_scale", "watching", "process_start"]

#: half the last digit of a ratio the watching report prints with three decimals
RATIO_DIGITS = 0.0005

# headers every family must print
EXPECTED = {
    "distributed": ["| processes", "bare rounds/s best / median", "agents / bare (medians)",
                    "deployed / agents (medians)", "slowest match"],
    "packing": ["| agents", "processes x agents each: rounds/s", "| fastest", "default (no -k)",
                "default / fastest", "1 x 8:", "2 x 4:", "rounds/s by --agent-nodes",
                "start-up s by --agent-nodes", "auto / none rounds/s"],
    "scaling": ["| agents", "processes x agents each", "rounds/s", "first round after (s)",
                "peak memory per process (MB)", "ms per round: publish / wait / other",
                "transport share", "| 8 "],
    "trade": ["| integrator", "rounds/step", "wall s per simulated s", "| rate (Hz)",
              "injected delay"],
    "realtime_scale": ["| agents", "packing (processes x agents)", "ticks started late",
                       "CPU ms per agent tick", "wall / simulated time", "default: 1 x 8",
                       "-k 1: 2 x 1", "agents / bare (medians)"],
    "process_start": ["| node processes", "CPU s of the run (median)", "| forked / exec",
                      "| forked / fresh server", "| fresh server ", "| exec "],
    "watching": ["| agents", "median with", "median without", "with / without",
                 "median of the pairs", "others' cores"],
    "bridge": ["| sigma (m, rad)", "| lag (s)", "noise floor", "measured: median / max",
               "true: median / max", "true / floor", "true below floor from (s)",
               "(A-2) alone (no noise, no lag"],
}


def _rows(tables, name):
    return [row for header, rows in tables if name in header for row in rows]


def _finished(tables, out):
    """Every run the family started finished ('3+3+3 of 3', '2 of 2')."""
    cells = [row["runs that finished"] for row in _rows(tables, "runs that finished")]
    assert cells, tables
    for cell in cells:
        done, total = cell.split(" of ")
        assert all(int(part) == int(total) for part in done.split("+")), cell


def _shapes_multiply(tables, out):
    """Each 'P x K' shape runs P processes of K agents: P K is the row's agent count."""
    rows = _rows(tables, "agents")
    assert rows, tables
    for row in rows:
        agents = int(row["agents"])
        shapes = re.findall(r"(\d+) x (\d+)", " ".join(v for k, v in row.items() if k != "agents"))
        assert shapes, row
        assert all(int(p) * int(k) == agents for p, k in shapes), row


def _trade(tables, out):
    """A lockstep round per stage: rounds per step are the integrator's stages."""
    stages = {"lie_euler": 1, "lie_heun": 2, "rkmk4": 4, "euler_proj": 1, "rk4_proj": 4}
    rows = _rows(tables, "rounds/step")
    assert rows, tables
    for row in rows:
        assert number(row["rounds/step"]) == stages[row["integrator"]], row


def _bridge(tables, out):
    """The noise floor of each row is 6 sqrt(2) (sigma sqrt(d) + sigma r) for the quick scene's
    triangles (d = 2, vertex radius 1), and every run drove its robots (a true diameter)."""
    rows = _rows(tables, "true / floor")
    assert rows, tables
    for row in rows:
        sigma = number(row["sigma (m, rad)"])
        floor = 6 * math.sqrt(2) * (sigma * math.sqrt(2) + sigma * 1.0)
        assert number(row["noise floor"]) == pytest.approx(floor, rel=5e-3), row
        assert row["true: median / max"] != "-", row


def _realtime_scale(tables, out):
    """The shapes multiply out; every one-agent-a-process row has its bare tick, whose processes
    cost some CPU a tick (median no more than the worst), and the agents' median over it is the
    quotient of the two medians; the packed rows have none."""
    _shapes_multiply(tables, out)
    rows = _rows(tables, "agents / bare (medians)")
    assert any("-k 1" in row["packing (processes x agents)"] for row in rows), tables
    for row in rows:
        bare = row["bare tick: CPU ms per tick per process (median / worst)"]
        if "-k 1" not in row["packing (processes x agents)"]:
            assert bare == "-" and row["agents / bare (medians)"] == "-", row
            continue
        median, worst = (float(v) for v in bare.split(" / "))
        assert 0 < median <= worst, row
        agents = float(row["CPU ms per tick per process (median / worst)"].split(" / ")[0])
        assert number(row["agents / bare (medians)"]) == pytest.approx(agents / median,
                                                                        rel=0.02), row


def _ratios(tables, out):
    """Every size ran with and without the monitor: its ratio is the medians' quotient."""
    rows = _rows(tables, "with / without")
    assert rows, tables
    for row in rows:
        on, off = number(row["median with"]), number(row["median without"])
        assert on > 0 and off > 0, row
        # to the medians' own rounding, and the ratio's (``RATIO_DIGITS``)
        assert number(row["with / without"]) == pytest.approx(on / off, rel=0.05,
                                                               abs=RATIO_DIGITS), row
        # each pair's ratio from its two runs' rates, and their median
        pairs = [float(a) / float(b) for a, b in zip(row["with the monitor (each run)"].split(),
                                                     row["without (each run)"].split())]
        shown = re.findall(r"([\d.]+) \(([\d.]+)/([\d.]+)\)",
                           row["each pair: with / without (others' cores)"])
        assert [float(p) for p, _, _ in shown] == pytest.approx(pairs, rel=0.05,
                                                                abs=RATIO_DIGITS), row
        assert all(float(c) >= 0 for _, a, b in shown for c in (a, b)), row
        assert number(row["median of the pairs"]) == pytest.approx(
            statistics.median(pairs), rel=0.05), row


def _start_ratios(tables, out):
    """Each way ran and finished; each ratio is the quotient of the medians it shows."""
    rows = {row["node processes"]: row for row in _rows(tables, "CPU s of the run (median)")}
    for name in ("forked", "fresh server", "exec"):
        assert rows[name]["runs that finished"] == "1 of 1", rows[name]
        assert number(rows[name]["CPU s of the run (median)"]) > 0, rows[name]
        assert number(rows[name]["rounds/s (median)"]) > 0, rows[name]
    forked = number(rows["forked"]["CPU s of the run (median)"])
    for over in ("exec", "fresh server"):
        cpu = forked / number(rows[over]["CPU s of the run (median)"])
        assert number(rows[f"forked / {over}"]["CPU s of the run (median)"]) == pytest.approx(
            cpu, rel=0.02, abs=0.002)


VALUES = {"distributed": _finished, "packing": _shapes_multiply, "scaling": _shapes_multiply,
          "graphs": None, "trade": _trade, "bridge": _bridge, "realtime": _finished,
          "realtime_scale": _realtime_scale, "watching": _ratios,
          "process_start": _start_ratios}


@pytest.mark.usefixtures("ros")  # the slot and domain of a ROS world; the family takes its own
@pytest.mark.parametrize("name", ROS_QUICK_FAMILIES)
def test_ros_family_quick(name, capsys):
    assert main([name, "--quick", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("# ")
    for failure in ("run failed", "Failed runs:"):   # a family reports, never hides, a failure
        assert failure not in out, f"{name}: a run inside the family failed"
    for text in EXPECTED.get(name, []):
        assert text in out, f"{name}: {text!r} missing from the output"
    if VALUES[name] is not None:
        VALUES[name](family_tables(out), out)
