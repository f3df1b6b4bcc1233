"""Process deaths in a running ensemble: a realtime soak with an agent killed at regular
intervals, and a lockstep run with several kills (``polymatch run --on-failure restart``).

Soak: the paper's 8 triangles in realtime (one agent per process, the monitor running, 20 Hz,
time scale 1, ``--hold`` past t_end so that it runs the whole time); every ``--interval``
seconds one agent process, chosen at random, is killed with SIGKILL by its PID.  Reported: the
deaths and restarts, the time until each restarted process was heard again (``back after``),
the final matching diameter (from the agents' final poses), and the resident memory of the
runner and of the processes that were never killed, at the start and at the end (a leak would
show as growth).

Lockstep: the same scene, dt 0.01, four processes of two agents (``-k 2``); ``--kills``
processes killed at random, spaced over the run.  Reported: restarts, time lost (the run's wall
time against an uninterrupted run of the same plan, measured in the same call) and the
deviation from the centralised simulation (``max vertex deviation``), which an exact resume
keeps at round-off.
"""

import json
import os
import random
import re
import signal
import subprocess
import sys
import tempfile
import time

NAME = "faults"
HELP = "process deaths: realtime soak with an agent killed every S s, lockstep with K kills"

FAILURE_KEY = "polymatch_failure"


def add_arguments(p):
    from ..options import at_least

    p.add_argument("--seconds", type=at_least(10), default=600,
                   help="wall-clock seconds of the realtime soak (default 600)")
    p.add_argument("--interval", type=at_least(5), default=30,
                   help="seconds between kills in the soak (default 30)")
    p.add_argument("--kills", type=at_least(1), default=5,
                   help="processes killed in the lockstep run (default 5)")
    p.add_argument("--seed", type=int, default=1, help="which processes die (default 1)")


def _nodes(run):
    """{node name: pid} of the run's processes (``-r __node:=NAME``), and the runner's pid."""
    from ..hosts.runs import argv_of, descendants, node_name

    out, runner = {}, None
    for pid in descendants(run.pid):
        argv = argv_of(pid)
        name = node_name(argv)
        if name is not None:
            out[name] = pid
        elif b"polymatch_ros.cli" in argv and b"timeout" not in argv:
            runner = pid
    return out, runner


def _rss_mib(pid):
    try:
        with open(f"/proc/{pid}/status") as fh:
            for line in fh:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024
    except OSError:
        pass
    return None


def _start(env, argv, bound):
    return subprocess.Popen(
        ["timeout", "-k", "5", str(bound), sys.executable, "-m", "polymatch_ros.cli"] + argv,
        env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def _failures(records):
    if not os.path.exists(records):
        return []
    with open(records, encoding="utf-8") as fh:
        return [json.loads(line) for line in fh if line.startswith('{"' + FAILURE_KEY)]


def _wait_up(run, names, seconds):
    """Until every process of ``names`` runs (or ``seconds`` passed); {name: pid}."""
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline and run.poll() is None:
        nodes, runner = _nodes(run)
        if runner and all(n in nodes for n in names):
            return nodes, runner
        time.sleep(0.5)
    return _nodes(run)


def soak(env, path, seconds, interval, rng, log):
    """The realtime soak; a dict of its figures."""
    with tempfile.TemporaryDirectory() as tmp:
        records = os.path.join(tmp, "soak.jsonl")
        run = _start(env, ["run", path, "--mode", "realtime", "--rate", "20", "--t-end",
                           str(seconds), "--hold", "1e9", "-q", "--run-records", records,
                           "--timeout", str(seconds + 120)], seconds + 180)
        agents = [f"agent_{i}" for i in range(8)]
        nodes, runner = _wait_up(run, agents + ["monitor"], 120)
        time.sleep(min(interval, 5))
        first = {n: _rss_mib(p) for n, p in nodes.items()} | {"runner": _rss_mib(runner)}
        killed, start = set(), time.monotonic()
        while time.monotonic() - start < seconds - interval and run.poll() is None:
            time.sleep(interval)
            victim = rng.choice(agents)
            nodes, _ = _nodes(run)
            if victim in nodes:
                log(f"soak: SIGKILL {victim} (pid {nodes[victim]})")
                os.kill(nodes[victim], signal.SIGKILL)
                killed.add(victim)
        time.sleep(max(0.0, seconds - (time.monotonic() - start) - 5))
        nodes, _ = _nodes(run)
        last = {n: _rss_mib(p) for n, p in nodes.items()} | {"runner": _rss_mib(runner)}
        out, _ = run.communicate(timeout=seconds + 200)
        failures = _failures(records)
    never = [n for n in first if n not in killed and first[n] and last.get(n)]
    return {"code": run.returncode, "failures": failures, "killed": len(killed),
            "memory": {n: (first[n], last[n]) for n in never}, "out": out,
            "diameter": _summary_diameter(out)}


def _summary_diameter(out):
    """The matching diameter of the summary table's first group (the final poses)."""
    rows = re.findall(r"^\S+\s+\d+\s+\S+\s+\S+\s+(\S+)\s+\S+\s+\S+\s*$", out or "", re.M)
    return float(rows[0]) if rows else None


def lockstep(env, path, kills, rng, log, t_end=6.0):
    """An uninterrupted lockstep run and one with ``kills`` deaths; their figures."""
    argv = ["run", path, "--t-end", str(t_end), "--dt", "0.01", "-k", "2", "--timeout", "900"]
    results = {}
    for label, n_kills in (("uninterrupted", 0), ("killed", kills)):
        with tempfile.TemporaryDirectory() as tmp:
            records = os.path.join(tmp, f"{label}.jsonl")
            t0 = time.monotonic()
            run = _start(env, argv + ["--run-records", records], 960)
            names = [f"agents_{i}_{i + 1}" for i in range(0, 8, 2)]
            _wait_up(run, names, 120)
            for k in range(n_kills):
                time.sleep(rng.uniform(3.0, 6.0))
                nodes, _ = _nodes(run)
                victim = rng.choice(names)
                if victim in nodes and run.poll() is None:
                    log(f"lockstep: SIGKILL {victim} ({k + 1}/{n_kills})")
                    os.kill(nodes[victim], signal.SIGKILL)
            out, _ = run.communicate(timeout=960)
            wall = time.monotonic() - t0
            found = re.search(r"max vertex deviation (\S+)", out)
            results[label] = {"code": run.returncode, "wall": wall,
                              "deviation": float(found.group(1)) if found else None,
                              "failures": _failures(records), "out": out}
    return results


def _soak_rows(s):
    backs = [f["back_after"] for f in s["failures"] if f.get("back_after") is not None]
    mem = s["memory"]
    growth = max((b - a for a, b in mem.values()), default=0.0)
    return [[str(s["killed"]), str(len(s["failures"])),
             str(sum(f.get("restarted_after") is not None for f in s["failures"])),
             f"{sum(backs) / len(backs):.1f} / {max(backs):.1f}" if backs else "-",
             "-" if s["diameter"] is None else f"{s['diameter']:.2e}",
             f"{mem.get('runner', (0, 0))[0]:.0f} -> {mem.get('runner', (0, 0))[1]:.0f}",
             f"{growth:+.1f}", str(s["code"])]]


def run(args, log):
    from domain_coordinator import domain_id

    from polymatch_ros.core.scenes.scene import resolve_scene_path
    from polymatch_ros.ros.network.environment import private_ros_environment

    from ..report import Report

    report = Report(NAME, "Process deaths (`python -m benchmarks faults`)")
    path = resolve_scene_path("congruent_triangles")
    rng = random.Random(args.seed)
    seconds, interval = (30, 10) if args.quick else (args.seconds, args.interval)
    kills = 1 if args.quick else args.kills
    with domain_id() as dom:
        env = private_ros_environment(dom)
        log(f"soak: {seconds} s, an agent killed every {interval} s")
        s = soak(env, path, seconds, interval, rng, log)
        log(f"lockstep: uninterrupted, then {kills} kills")
        lk = lockstep(env, path, kills, rng, log, 2.0 if args.quick else 6.0)
    report.table(
        ["distinct agents killed", "deaths", "restarted", "back after (s) mean / max",
         "final matching diameter", "runner RSS (MiB) start -> end",
         "largest RSS growth of a never-killed process (MiB)", "exit"],
        _soak_rows(s),
        caption=f"Realtime soak: 8 triangles, one agent per process, 20 Hz, {seconds} s, "
        f"a random agent process SIGKILLed every {interval} s (seed {args.seed})",
    )
    ref, hit = lk["uninterrupted"], lk["killed"]
    lost = (hit["wall"] - ref["wall"]) / max(1, len(hit["failures"]))
    report.table(
        ["run", "deaths", "wall s", "wall s lost per death", "max vertex deviation", "exit"],
        [["uninterrupted", "0", f"{ref['wall']:.1f}", "-", f"{ref['deviation']}",
          str(ref["code"])],
         [f"{kills} kills", str(len(hit["failures"])), f"{hit['wall']:.1f}", f"{lost:.1f}",
          f"{hit['deviation']}", str(hit["code"])]],
        caption=f"Lockstep: 8 triangles in 4 processes (-k 2), dt 0.01, t_end "
        f"{2 if args.quick else 6} (not yet matched: exit 3 is the scene's verdict); the "
        "deviation is from the centralised run",
    )
    return report
