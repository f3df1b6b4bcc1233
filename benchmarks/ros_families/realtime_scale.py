"""Realtime at the scale of a swarm: N agents at R Hz, with the default packing and one agent a
process, ticks started late, CPU per tick, wall time against simulated time.

For each N (default 8, 64, 256, 1024) and rate (default 10, 20, 50 Hz), one run of N congruent
triangles (first-order model, time scale 1, ``--seconds`` simulated seconds) through `polymatch
run --mode realtime` with the monitor, as users run it: with the packing it picks without -k,
and with ``-k 1`` where N agent processes, the runner and the monitor fit the 32 DDS
participants LOCALHOST discovery reaches (``--k1-agents``, default 8 and 16).  The runs of one
size alternate between packings, so the machine's drift hits them alike.  From the agents' run
records: the share of ticks that started more than one period late; each process's CPU time
per tick (median and worst over processes, every thread); the wall time the ticks took over the
simulated time they covered (1.00: real time held); and whether the run ended matched (exit 0)
or only ran to t_end (exit 3).

Beside each one-agent-a-process run, the bare transport's tick at the same size and rate
(``bare_exchange tick``: N processes publishing one AgentState a tick and taking the newest of
each peer's, with the agents' QoS and no numerics): what rclpy and Fast DDS alone cost a
process a tick, and the agents' CPU over it.
"""

import os
import re
import sys
import time

NAME = "realtime_scale"
HELP = "realtime at 8 ... 1024 agents and 10 ... 50 Hz: late ticks, CPU per tick, wall vs sim"


def add_arguments(p):
    from ..options import at_least, int_list

    p.add_argument("--agents", type=int_list(2), default=[8, 64, 256, 1024], metavar="N,N,...",
                   help="ensemble sizes (default 8,64,256,1024)")
    p.add_argument("--rates", type=int_list(1), default=[10, 20, 50], metavar="R,R,...",
                   help="tick rates in Hz (default 10,20,50)")
    p.add_argument("--k1-agents", type=int_list(2), default=[8, 16], metavar="N,N,...",
                   help="sizes also run one agent a process (default 8,16)")
    p.add_argument("--seconds", type=at_least(1), default=10,
                   help="simulated (and, in real time, wall-clock) seconds per run (default 10)")


def _scene_yaml(n, seconds):
    return (f"name: swarm_{n}\ndimension: 2\nseed: 1\nmodel: {{order: 1}}\n"
            f"integrator: {{method: rkmk4, dt: 0.01}}\ntime: {{t_end: {float(seconds)!r}}}\n"
            f"groups:\n  - {{name: triangles, shape: triangle, count: {n}}}\n")


def _one_run(env, path, rate, seconds, k, records):
    """One realtime run -> a dict of its figures, or a dict with ``failed``."""
    from .ros_runs import agent_records, run_cli

    bound = int(seconds * 3 + 90)
    argv = ["run", path, "--mode", "realtime", "--rate", str(rate), "--time-scale", "1",
            "--hold", "1e9", "-q", "--no-compare", "--run-records", records,
            "--timeout", str(bound - 20)]
    if k is not None:
        argv += ["-k", str(k)]
    began = time.monotonic()
    out = run_cli(env, argv, bound)
    took = time.monotonic() - began
    recs = [r for r in agent_records(records) if r.finished and r.steps]
    if not recs or out.returncode not in (0, 3):
        errors = [ln for ln in out.stderr.splitlines() if "error" in ln]
        return {"failed": errors[-1][:80] if errors else f"exit {out.returncode}", "took": took}
    ticks = sum(r.steps for r in recs)
    cpu = sorted(r.ms_per_round["cpu"] for r in recs if "cpu" in r.ms_per_round)
    wall = max(r.steps / r.rounds_per_second for r in recs if r.rounds_per_second > 0)
    return {"late": sum(r.late_ticks for r in recs) / max(1, ticks),
            "cpu_median": cpu[len(cpu) // 2] if cpu else float("nan"),
            "cpu_worst": cpu[-1] if cpu else float("nan"),
            "processes": len(recs), "agents_per_process": max(len(r.agents) for r in recs),
            "wall_over_sim": wall / max(r.t for r in recs), "matched": out.returncode == 0,
            "took": took}


def _bare_ticks(env, n, rate, seconds):
    """CPU ms a tick of each of ``n`` bare tick processes (``bare_exchange tick``), sorted; the
    processes that did not hear every peer are left out (empty: none finished)."""
    from .ros_runs import run_parallel

    argv = ["-m", "benchmarks.ros_families.bare_exchange", "tick"]
    outs = run_parallel([[sys.executable, *argv, str(i), str(n), str(rate), str(seconds)]
                         for i in range(n)], env, int(seconds * 3 + 60))
    found = [re.search(r"CPU ([0-9.]+) ms a tick .*; (\d+) of (\d+) peers heard", o)
             for o in outs]
    return sorted(float(m.group(1)) for m in found if m and m.group(2) == m.group(3))


def _bare_cells(got, bare):
    """(bare CPU ms a tick median / worst, agents' median over the bare median) of a row."""
    if not bare:
        return ["-", "-"]
    median = bare[len(bare) // 2]
    ratio = f"{got['cpu_median'] / median:.2f}" if "cpu_median" in got else "-"
    return [f"{median:.2f} / {bare[-1]:.2f}", ratio]


def _row(n, rate, packing, got):
    if "failed" in got:
        return [str(n), f"{rate:g}", packing, "-", "-", "-", "-", f"failed: {got['failed']}"]
    return [str(n), f"{rate:g}", f"{packing}: {got['processes']} x {got['agents_per_process']}",
            f"{got['late']:.1%}", f"{got['cpu_median']:.2f} / {got['cpu_worst']:.2f}",
            f"{got['cpu_median'] / got['agents_per_process']:.3f}",
            f"{got['wall_over_sim']:.2f}", "matched" if got["matched"] else "ran to t_end"]


def run(args, log):
    from ..report import Report
    from ..timing import load_span
    from .ros_runs import private_runs, write_scene

    report = Report(NAME, "Realtime at the scale of a swarm (`python -m benchmarks "
                          "realtime_scale`)")
    sizes = [8] if args.quick else args.agents
    rates = [20] if args.quick else args.rates
    seconds = 2 if args.quick else args.seconds
    k1 = [2] if args.quick else args.k1_agents
    rows = []
    load = [os.getloadavg()]
    with private_runs() as (tmp, env):
        for n in sorted(set(sizes) | set(k1)):
            path = write_scene(tmp, f"swarm_{n}.yaml", _scene_yaml(n, seconds))
            for rate in rates:
                packings = ([("default", None)] if n in sizes else [])
                packings += [("-k 1", 1)] if n in k1 else []
                for label, k in packings:
                    log(f"{n} agents at {rate:g} Hz, {label}")
                    records = os.path.join(tmp, f"rt_{n}_{rate}_{label.replace(' ', '')}.jsonl")
                    got = _one_run(env, path, rate, seconds, k, records)
                    bare = _bare_ticks(env, n, rate, seconds) if k == 1 else []
                    rows.append(_row(n, rate, label, got) + _bare_cells(got, bare))
                    load.append(os.getloadavg())
    report.table(
        ["agents", "rate (Hz)", "packing (processes x agents)", "ticks started late",
         "CPU ms per tick per process (median / worst)", "CPU ms per agent tick",
         "wall / simulated time", "end", "bare tick: CPU ms per tick per process (median / "
         "worst)", "agents / bare (medians)"],
        rows,
        caption=f"Realtime, N congruent triangles (first order), time scale 1, {seconds} "
        f"simulated s per run, the monitor running; {load_span(load)}",
    )
    report.text(
        "- A tick is late when it starts more than one period after its due time.",
        "- CPU per tick is the process's CPU time over its ticks (every thread); per agent "
        "tick: over the agents it hosts.",
        "- wall / simulated: the wall-clock time of the ticks over the simulated time they "
        "covered; 1.00 holds real time.",
        "- bare tick (one agent a process only): the same number of processes publishing one "
        "AgentState a tick and taking each peer's newest, with the agents' QoS, no numerics and "
        "no checks (`python -m benchmarks.ros_families.bare_exchange tick`): what rclpy and "
        "Fast DDS alone cost a process a tick here.",
    )
    return report
