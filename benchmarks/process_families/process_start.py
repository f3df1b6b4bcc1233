"""What starting a run's node processes costs: the CPU of a whole run with its node processes
forked from a fork server that is the runner's own fork (as shipped, ``ros/process/forked.py``),
from a fork server that is a fresh interpreter importing the node modules itself
(``multiprocessing``'s own start, which the runner falls back to), and with each started by exec
(the fork server switched off in the runner), side by side.

Each repeat runs the paper's 8 triangles in lockstep (rkmk4, one agent per process and the
monitor: nine node processes) once each way, in rotating order.  The CPU is that of every
process of the run — `timeout`, the runner, the fork server, the nodes — however it ended:
this process is their subreaper (``PR_SET_CHILD_SUBREAPER``), so a process that outlives its
parent (the fork server, once the runner has gone) is reaped here, and the kernel's count of
the reaped children's CPU (``RUSAGE_CHILDREN``) holds all of them.  Reported per variant: the
run's CPU seconds and wall seconds (medians over repeats) and the agents' rounds/s; then the
quotients of the medians.  Short runs show the start-up; ``--t-end`` lengthens them.
"""

import ctypes
import os
import resource
import statistics
import subprocess
import sys
import time

NAME = "process_start"
HELP = "the CPU of a run with its node processes forked (runner's fork, fresh server) or exec'd"

#: the runner with its fork server switched off: every node process started by exec
EXEC_ONLY = (
    "import sys\n"
    "from polymatch_ros.ros.process import forked\n"
    "forked.start = lambda argv, env: None\n"
    "from polymatch_ros.cli import main\n"
    "sys.exit(main(sys.argv[1:]))\n"
)
#: the runner with a fork server that is a fresh interpreter (its fork switched off)
FRESH_SERVER = (
    "import sys\n"
    "from polymatch_ros.ros.process import forked\n"
    "forked._fork_server_from_here = lambda also=(): False\n"
    "from polymatch_ros.cli import main\n"
    "sys.exit(main(sys.argv[1:]))\n"
)
HEADS = {"forked": ["-m", "polymatch_ros.cli"], "fresh server": ["-c", FRESH_SERVER],
         "exec": ["-c", EXEC_ONLY]}
VARIANTS = tuple(HEADS)
PR_SET_CHILD_SUBREAPER = 36


def add_arguments(p):
    from ..options import at_least

    p.add_argument("--t-end", type=at_least(0.05), default=None,
                   help="simulated seconds of each run, dt 0.05 (default 0.5: 10 rounds; "
                   "--quick: 0.1)")


def _children_cpu():
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _reap_all():
    """Wait for every process this one is the parent or subreaper of (they all end with the
    run: the runner ends its children, the fork server ends with the runner)."""
    while True:
        try:
            os.waitpid(-1, 0)
        except ChildProcessError:
            return


def one_run(env, variant, t_end, records):
    """(whether all 8 agents finished, CPU s of all the run's processes, wall s, the agents'
    median rounds/s)."""
    from ..ros_families.ros_runs import agent_records

    argv = ["timeout", "-k", "5", "300", sys.executable, *HEADS[variant], "run",
            "congruent_triangles", "-k", "1", "--integrator", "rkmk4", "--dt", "0.05",
            "--t-end", str(t_end), "--no-compare", "-q", "--run-records", records,
            "--timeout", "240"]
    cpu, start = _children_cpu(), time.monotonic()
    proc = subprocess.Popen(argv, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    proc.wait()
    wall = time.monotonic() - start
    _reap_all()
    agents = agent_records(records)
    finished = len(agents) == 8 and all(r.finished for r in agents)
    rates = [r.rounds_per_second for r in agents if r.rounds_per_second]
    return finished, _children_cpu() - cpu, wall, (statistics.median(rates) if rates else None)


def run(args, log):
    from ..report import Report
    from ..ros_families.ros_runs import private_runs

    report = Report(NAME, "Starting a run's node processes: forked or exec'd "
                          "(`python -m benchmarks process_start`)")
    if ctypes.CDLL("libc.so.6", use_errno=True).prctl(PR_SET_CHILD_SUBREAPER, 1) != 0:
        report.text("Not measured: this system does not let a process reap its descendants "
                    "(PR_SET_CHILD_SUBREAPER), so the CPU of the fork server's processes "
                    "cannot be counted.")
        return report
    repeats = 1 if args.quick else (args.repeats or 5)
    t_end = args.t_end if args.t_end is not None else (0.1 if args.quick else 0.5)
    results = {v: [] for v in VARIANTS}
    with private_runs() as (tmp, env):
        for i in range(repeats):
            for variant in VARIANTS[i % 3:] + VARIANTS[:i % 3]:
                records = os.path.join(tmp, f"{variant}_{i}.jsonl")
                results[variant].append(one_run(env, variant, t_end, records))
                finished, cpu, wall, rate = results[variant][-1]
                log(f"{variant} #{i + 1}: {'finished' if finished else 'FAILED'}, CPU "
                    f"{cpu:.2f} s, wall {wall:.2f} s, {rate} rounds/s")
    _table(report, results, t_end, repeats)
    return report


def _table(report, results, t_end, repeats):
    rows, medians = [], {}
    for variant in VARIANTS:
        runs = results[variant]
        rates = [r[3] for r in runs if r[3] is not None]
        medians[variant] = (statistics.median(r[1] for r in runs),
                            statistics.median(r[2] for r in runs))
        rows.append([variant, f"{medians[variant][0]:.2f}", f"{medians[variant][1]:.2f}",
                     " / ".join(f"{r[1]:.2f}" for r in runs),
                     "-" if not rates else f"{statistics.median(rates):.1f}",
                     f"{sum(r[0] for r in runs)} of {len(runs)}"])
    for over in ("exec", "fresh server"):
        (cpu_f, wall_f), (cpu_o, wall_o) = medians["forked"], medians[over]
        rows.append([f"forked / {over}", f"{cpu_f / cpu_o:.3f}", f"{wall_f / wall_o:.3f}", "",
                     "", ""])
    report.table(
        ["node processes", "CPU s of the run (median)", "wall s (median)", "CPU s, each run",
         "rounds/s (median)", "runs that finished"],
        rows,
        caption=f"8 triangles in lockstep, rkmk4, dt 0.05, t_end {t_end:g}, one agent per "
        f"process and the monitor (9 node processes), {repeats} repeats in rotating order; CPU "
        "of every process of the run",
    )
