"""Can the agents hold their rate? Realtime ticks started late, and CPU per tick, against the rate.

The paper's 8 triangles, one agent process each (`polymatch run --mode realtime -k 1`; the
default packing, and larger ensembles: ``realtime_scale``), the monitor running, time scale 1,
at 25 ... 200 Hz, each rate run R times in turn (the rates alternate, so that the machine's
drift hits them alike).  From the agents' run
records: the share of ticks that started more than one period late (all agents, and the
worst agent), and each agent process's CPU time per tick over its ticks (every thread: the
middleware's too).  8 x CPU per tick x rate, over the machine's cores, is the share of the
machine the agents need: past 1 they cannot hold the rate, and well before it other load on
a shared machine makes ticks late.
"""

import os
import tempfile

NAME = "realtime"
HELP = "realtime: ticks started late and CPU per tick of 8 agents (with the monitor) vs the rate"

RATES = (25.0, 50.0, 100.0, 200.0)


def add_arguments(p):
    from ..options import at_least

    p.add_argument("--seconds", type=at_least(1), default=10,
                   help="wall-clock seconds of ticking per run (default 10)")


def _run_rate(env, path, rate, seconds, tmp, tag):
    """One realtime run: (late ticks, ticks, worst agent's late share, CPU ms per tick of each
    agent), or None if the run failed."""
    from .ros_runs import agent_records, run_cli

    records = os.path.join(tmp, f"rt_{rate:g}_{tag}.jsonl")
    run_cli(env, ["run", path, "--mode", "realtime", "-k", "1", "--rate", str(rate),
                  "--time-scale", "1",
                  "--t-end", str(seconds), "--hold", "1e9", "-q", "--no-compare",
                  "--run-records", records, "--timeout", str(seconds + 120)], seconds + 180)
    recs = [r for r in agent_records(records) if r.finished and r.steps]
    if not recs:
        return None
    late = sum(r.late_ticks for r in recs)
    ticks = sum(r.steps for r in recs)
    worst = max(r.late_ticks / r.steps for r in recs)
    cpu = [r.ms_per_round["cpu"] for r in recs if "cpu" in r.ms_per_round]
    return late, ticks, worst, cpu


def _row(rate, runs, n_agents, cores):
    """A table row from the runs at one rate."""
    import numpy as np

    done = [r for r in runs if r is not None]
    if not done:
        return [f"{rate:g}", "-", "-", "-", "-", f"0 of {len(runs)}"]
    late = sum(r[0] for r in done) / max(1, sum(r[1] for r in done))
    worst = max(r[2] for r in done)
    cpu = float(np.median([c for r in done for c in r[3]])) if any(r[3] for r in done) else None
    need = n_agents * cpu * rate / 1e3 / cores if cpu is not None else None
    return [f"{rate:g}", f"{late:.1%}", f"{worst:.1%}",
            "-" if cpu is None else f"{cpu:.2f}", "-" if need is None else f"{need:.2f}",
            f"{len(done)} of {len(runs)}"]


def run(args, log):
    from domain_coordinator import domain_id

    from polymatch_ros.core.scenes.scene import load_scene, resolve_scene_path
    from polymatch_ros.ros.network.environment import private_ros_environment

    from ..report import Report

    report = Report(NAME, "Holding the realtime rate (`python -m benchmarks realtime`)")
    path = resolve_scene_path("congruent_triangles")
    n_agents = load_scene(path).model.n_agents
    rates = (50.0,) if args.quick else RATES
    seconds = 1 if args.quick else args.seconds
    repeats = 1 if args.quick else (args.repeats or 2)
    cores = os.cpu_count() or 1
    runs = {rate: [] for rate in rates}
    with tempfile.TemporaryDirectory() as tmp, domain_id() as dom:
        env = private_ros_environment(dom)
        for r in range(repeats):
            for rate in rates:
                log(f"repeat {r + 1}/{repeats}: {rate:g} Hz for {seconds} s")
                runs[rate].append(_run_rate(env, path, rate, seconds, tmp, r))
    report.table(
        ["rate (Hz)", "ticks started late", "worst agent", "agent CPU ms per tick (median)",
         f"agents' CPU / {cores} cores", "runs that finished"],
        [_row(rate, runs[rate], n_agents, cores) for rate in rates],
        caption=f"Realtime, the paper's {n_agents} triangles (config/congruent_triangles.yaml), "
        f"one agent per process, the monitor running, time scale 1, {seconds} s of ticks per "
        f"run, {repeats} runs per rate in turn",
    )
    report.text(
        "- A tick is late when it starts more than one period after its due time; a late "
        "agent then steps in a burst on stale poses until it is back on schedule.",
        "- CPU per tick is the agent process's CPU time over its ticks divided by their number "
        "(every thread of the process: the middleware's receive and send work too).",
    )
    return report
