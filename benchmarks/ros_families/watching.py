"""What watching costs: lockstep rounds/s of `polymatch run` with and without the monitor.

For each N (default 8, 64, 1024), N congruent triangles (first-order model, rkmk4, R rounds:
a few seconds a run) through `polymatch run` with its default packing, with the monitor and
with ``--no-monitor``, the two alternating ``--repeats`` times, which one first alternating
too (so that the machine's drift hits them alike).  A run's
rate is the mean of its agent processes' rounds/s (their run records); the table gives the
medians and their ratio, with the monitor over without: the monitor reads the agents' states at
its report rate (``agents.state_stride``), decodes only the steps it reports
(``nodes.held_steps``), and should cost the run next to nothing.

The machine is shared: each run also gives the CPU the rest of the machine took meanwhile
(``others``: the busy time of /proc/stat less the run's own processes' CPU time, in cores), and
each pair of runs, one after the other, its own ratio, which the machine's drift between the
pairs does not touch.
"""

import os
import resource
import time

NAME = "watching"
HELP = "lockstep rounds/s of `polymatch run` with the monitor over without, 8 ... 1024 agents"


def add_arguments(p):
    from ..options import int_list

    p.add_argument("--agents", type=int_list(2), default=[8, 64, 1024], metavar="N,N,...",
                   help="ensemble sizes (default 8,64,1024)")
    p.add_argument("--rounds", type=int_list(8), default=[160000, 80000, 8000],
                   metavar="R,R,...", help="rounds per run at each size, the last for any "
                   "further size (default 160000,80000,8000: several seconds a run)")


def _scene_yaml(n, steps, dt):
    return (f"name: watching_{n}\ndimension: 2\nseed: 1\nmodel: {{order: 1}}\n"
            f"integrator: {{method: rkmk4, dt: {dt}}}\ntime: {{t_end: {steps * dt!r}}}\n"
            f"groups:\n  - {{name: triangles, shape: triangle, count: {n}}}\n")


def _cpu_now():
    """(wall s, CPU s the whole machine spent busy (/proc/stat), CPU s of our ended children)."""
    with open("/proc/stat", encoding="ascii") as fh:
        jiffies = [int(v) for v in fh.readline().split()[1:9]]
    busy = (sum(jiffies) - jiffies[3] - jiffies[4]) / os.sysconf("SC_CLK_TCK")  # less idle, io
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.monotonic(), busy, kids.ru_utime + kids.ru_stime


def _rate(env, path, timeout, extra):
    """(the mean rounds/s of the run's agent processes, or nan if it failed; the cores the
    rest of the machine kept busy meanwhile)."""
    import numpy as np

    from .ros_runs import agent_records, run_cli

    records = path + ".records.jsonl"
    if os.path.exists(records):
        os.remove(records)
    before = _cpu_now()
    out = run_cli(env, ["run", path, "--no-compare", "--hold", "1e9", "--timeout",
                        str(timeout - 10), "-q", "--run-records", records, *extra], timeout)
    wall, busy, ours = (b - a for a, b in zip(before, _cpu_now()))
    rates = [r.rounds_per_second for r in agent_records(records) if r.finished]
    ok = out.returncode in (0, 3) and rates  # 3: ran to t_end without matching yet
    return (float(np.mean(rates)) if ok else float("nan")), max(0.0, busy - ours) / wall


def _median(values):
    import numpy as np

    done = [v for v in values if v == v]
    return float(np.median(done)) if done else float("nan")


def run(args, log):
    from ..report import Report
    from ..timing import load_span
    from .ros_runs import private_runs, write_scene

    report = Report(NAME, "What watching costs (`python -m benchmarks watching`)")
    sizes = [8] if args.quick else args.agents
    rounds = [40] if args.quick else args.rounds
    repeats = 1 if args.quick else (args.repeats or 3)
    rows, load, captions = [], [os.getloadavg()], []
    with private_runs() as (tmp, env):
        for i, n in enumerate(sizes):
            steps = max(2, rounds[min(i, len(rounds) - 1)] // 4)  # rkmk4: 4 rounds a step
            captions.append(f"{n}: {4 * steps}")
            path = write_scene(tmp, f"watching_{n}.yaml", _scene_yaml(n, steps, 0.01))
            timeout = 120 + n * steps // 500
            runs = {"with": [], "without": []}
            others = {"with": [], "without": []}
            for r in range(repeats):
                pair = (("with", []), ("without", ["--no-monitor"]))
                for label, extra in pair if r % 2 == 0 else pair[::-1]:
                    log(f"{n} agents, repeat {r + 1}/{repeats}, {label} the monitor")
                    rate, busy = _rate(env, path, timeout, extra)
                    runs[label].append(rate)
                    others[label].append(busy)
                    load.append(os.getloadavg())
            rows.append(_row(n, runs, others))
    report.table(
        ["agents", "with the monitor (each run)", "without (each run)", "median with",
         "median without", "with / without", "each pair: with / without (others' cores)",
         "median of the pairs"],
        rows,
        caption=f"Lockstep rounds/s, N congruent triangles, rkmk4, rounds a run by N "
        f"({', '.join(captions)}), default packing, {repeats} alternating runs each; "
        f"{load_span(load)}",
    )
    report.text(
        "- others' cores: the CPU the rest of the machine took during a run (its /proc/stat "
        "busy time less the run's own processes'), in cores, for the run with the monitor / "
        "the one without.",
        "- median of the pairs: the median of each pair's own ratio (two runs back to back).",
    )
    return report


def _row(n, runs, others):
    on, off = _median(runs["with"]), _median(runs["without"])
    pairs = [a / b for a, b in zip(runs["with"], runs["without"])]
    each = " ".join(f"{p:.3f} ({a:.1f}/{b:.1f})"
                    for p, a, b in zip(pairs, others["with"], others["without"]))
    return [str(n), " ".join(f"{v:.0f}" for v in runs["with"]),
            " ".join(f"{v:.0f}" for v in runs["without"]), f"{on:.0f}", f"{off:.0f}",
            f"{on / off:.3f}" if off == off else "-", each, f"{_median(pairs):.3f}"]
