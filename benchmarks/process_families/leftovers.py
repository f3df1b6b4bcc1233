"""What a run leaves in /dev/shm, and what removing it costs: lockstep rounds/s with the
runner's sweep of the Fast DDS files its dead children left and without it, side by side.

Under ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST rmw_fastrtps gives every participant a
shared-memory transport of its own, whatever the profile says (``supervisor.shm``); each
process makes a segment and its lock file in /dev/shm, and one that is killed or ends before
rclpy let go of its last node leaves them.  Once its processes have ended, the runner removes
every such file that appeared during the run and whose owner has died (``ShmSweep``).  Each
repeat runs the paper's 8 triangles in lockstep (rkmk4, one agent per process, the monitor
running) twice, in alternating order: as shipped, and with the runner's sweep switched off in
that process.  Reported per variant:
the agents' rounds/s (median over agents, then over repeats), the run's wall time, the
segments its processes made (seen here, through the maps of every process under the run)
and the /dev/shm entries of them left after it ended; then shipped / off.
"""

import contextlib
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time

NAME = "leftovers"
HELP = "/dev/shm after a run, and lockstep rounds/s with and without the runner's clean-up"

#: the runner with its sweep switched off: nothing removed
SWEEP_OFF = (
    "import sys\n"
    "from polymatch_ros.ros.supervisor import shm\n"
    "shm.ShmSweep.remove_dead = lambda self, wait=0.0: []\n"
    "from polymatch_ros.cli import main\n"
    "sys.exit(main(sys.argv[1:]))\n"
)
VARIANTS = ("shipped", "sweep off")


def add_arguments(p):
    from ..options import at_least

    p.add_argument("--t-end", type=at_least(0.1), default=4.0,
                   help="simulated seconds of each run, dt 0.05 (default 4: 320 rounds)")


def _segments_under(root, seen, stop):
    """Note, until ``stop``, the Fast DDS segments mapped by each process under ``root``."""
    from ..hosts.runs import descendants

    while not stop.is_set():
        for pid in [root, *descendants(root)]:
            try:
                with open(f"/proc/{pid}/maps") as fh:
                    seen |= {line.split()[-1] for line in fh if "/dev/shm/fastrtps_" in line}
            except OSError:
                continue
        stop.wait(0.2)


def one_run(env, variant, t_end, records):
    """(agents' median rounds/s or None, wall s, segments made, /dev/shm entries left)."""
    from ..ros_families.ros_runs import agent_records

    head = ["-c", SWEEP_OFF] if variant == "sweep off" else ["-m", "polymatch_ros.cli"]
    argv = ["timeout", "-k", "5", "300", sys.executable, *head, "run", "congruent_triangles",
            "-k", "1", "--integrator", "rkmk4", "--dt", "0.05", "--t-end", str(t_end),
            "--no-compare", "-q", "--run-records", records, "--timeout", "240"]
    seen, stop = set(), threading.Event()
    start = time.monotonic()
    proc = subprocess.Popen(argv, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    watch = threading.Thread(target=_segments_under, args=(proc.pid, seen, stop), daemon=True)
    watch.start()
    proc.wait()
    wall = time.monotonic() - start
    stop.set()
    watch.join()
    left = [p for s in seen for p in (s, s + "_el") if os.path.exists(p)]
    rates = [r.rounds_per_second for r in agent_records(records) if r.rounds_per_second]
    return (statistics.median(rates) if rates else None), wall, len(seen), left


def run(args, log):
    from domain_coordinator import domain_id

    from polymatch_ros.ros.network.environment import private_ros_environment

    from ..report import Report

    report = Report(NAME, "What a run leaves in /dev/shm (`python -m benchmarks leftovers`)")
    t_end = 0.5 if args.quick else args.t_end
    repeats = 1 if args.quick else (args.repeats or 3)
    results = {v: [] for v in VARIANTS}
    with tempfile.TemporaryDirectory() as tmp, domain_id() as dom:
        env = private_ros_environment(dom)
        for i in range(repeats):
            for variant in (VARIANTS if i % 2 == 0 else VARIANTS[::-1]):
                records = os.path.join(tmp, f"{variant.replace(' ', '_')}_{i}.jsonl")
                results[variant].append(one_run(env, variant, t_end, records))
                rate, wall, made, left = results[variant][-1]
                log(f"{variant} #{i + 1}: {rate} rounds/s, {wall:.1f} s, {made} segments, "
                    f"{len(left)} entries left")
                _remove(left)
    rows, medians = [], {}
    for variant in VARIANTS:
        runs = results[variant]
        rates = [r[0] for r in runs if r[0] is not None]
        medians[variant] = (statistics.median(rates) if rates else None,
                            statistics.median(r[1] for r in runs))
        rows.append([variant, _fmt(medians[variant][0]), f"{medians[variant][1]:.1f}",
                     " / ".join(str(r[2]) for r in runs),
                     " / ".join(str(len(r[3])) for r in runs), f"{len(rates)} of {len(runs)}"])
    (rate_on, wall_on), (rate_off, wall_off) = medians["shipped"], medians["sweep off"]
    ratio = "-" if not (rate_on and rate_off) else f"{rate_on / rate_off:.3f}"
    rows.append(["shipped / off", ratio, f"{wall_on / wall_off:.3f}", "", "", ""])
    report.table(
        ["runner", "rounds/s (median)", "wall s (median)", "segments made, each run",
         "/dev/shm entries left, each run", "runs with records"],
        rows,
        caption=f"8 triangles in lockstep, rkmk4, dt 0.05, t_end {t_end:g} "
        f"({int(round(t_end / 0.05)) * 4} rounds), one agent per process and the monitor, "
        f"{repeats} alternating repeats; entries: a segment and its lock file",
    )
    return report


def _remove(entries):
    """Remove a run's own entries left (the sweep-off runs') whose owner no longer lives."""
    from polymatch_ros.ros.supervisor.shm import lock_held

    for path in entries:
        if not lock_held(path.removesuffix("_el") + "_el"):
            with contextlib.suppress(FileNotFoundError):
                os.unlink(path)


def _fmt(value):
    return "-" if value is None else f"{value:.1f}"
