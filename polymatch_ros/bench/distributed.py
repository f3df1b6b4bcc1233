"""Lockstep rounds per second over the ROS node set, against the bare transport's limit.

For N = 4, 8, 16, 32 agent processes (one agent each) on this machine:

  bare     ``python -m polymatch_ros.bench.bare_exchange``: N processes exchanging one
           Float64MultiArray per round all-to-all with the agents' stage QoS and executor,
           no numerics — the transport's limit;
  agents   ``polymatch run`` in lockstep without the monitor (the agents alone): congruent
           triangles, rkmk4 (4 rounds per step), the same number of rounds.

Each agent reports its own rounds/s and how long after its node was created every
peer was matched; the table gives the mean rate and the slowest match.  Every ROS
process runs with loopback discovery, a domain id reserved for the run, and a timeout.
"""

import os
import re
import subprocess
import sys
import tempfile
import time

NAME = "distributed"
HELP = "lockstep rounds/s of the agent processes vs the bare rclpy exchange, N = 4 ... 32"
ORDER = 60


def add_arguments(p):
    from .options import at_least, int_list
    p.add_argument("--agents", type=int_list(2), default=[4, 8, 16, 32], metavar="N,N,...",
                   help="numbers of agent processes (default 4,8,16,32)")
    p.add_argument("--rounds", type=at_least(8), default=400, help="rounds per run (default 400)")
    p.add_argument("--executor", choices=("single", "events"), default="single",
                   help="bare exchange executor (agents use the SingleThreadedExecutor)")


def _scene_yaml(n, steps, dt):
    return (f"name: bench_{n}\ndimension: 2\nseed: 1\nmodel: {{order: 1}}\n"
            f"integrator: {{method: rkmk4, dt: {dt}}}\ntime: {{t_end: {steps * dt!r}}}\n"
            f"groups:\n  - {{name: triangles, shape: triangle, count: {n}}}\n")


def _run_bare(n, rounds, executor, env, timeout):
    procs = [subprocess.Popen(["timeout", "-k", "5", str(timeout), sys.executable, "-m",
                               "polymatch_ros.bench.bare_exchange", str(i), str(n), str(rounds),
                               "--executor", executor],
                              env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
             for i in range(n)]
    rates, matched = [], []
    for p in procs:
        out, _ = p.communicate(timeout=timeout + 10)
        m = re.search(r"([0-9.]+) rounds/s .* matched after ([0-9.]+) s", out)
        if m:
            rates.append(float(m.group(1)))
            matched.append(float(m.group(2)))
    return rates, matched, len(procs)


def _run_agents(n, rounds, env, timeout, workdir):
    steps = max(1, rounds // 4)
    path = os.path.join(workdir, f"bench_{n}.yaml")
    with open(path, "w") as fh:
        fh.write(_scene_yaml(n, steps, 0.01))
    t0 = time.monotonic()
    proc = subprocess.run(["timeout", "-k", "5", str(timeout), sys.executable, "-m", "polymatch_ros.cli", "run",
                           path, "--no-monitor", "--no-compare", "--timeout", str(timeout - 10), "-q", "-v"],
                          env=env, capture_output=True, text=True)
    wall = time.monotonic() - t0
    rates = [float(x) for x in re.findall(r"^agent \d+: finished .* \(\d+ rounds, ([0-9.]+) rounds/s", proc.stdout,
                                          re.M)]
    matched = [float(x) for x in re.findall(r"peers matched after ([0-9.]+) s", proc.stdout)]
    return rates, matched, proc.returncode, wall, proc.stdout + proc.stderr


def run(args, log):
    import numpy as np
    from domain_coordinator import domain_id

    from ..ros_env import ros_environment
    from .report import Report

    sizes = [4] if args.quick else args.agents
    rounds = 40 if args.quick else args.rounds
    report = Report(NAME, "Lockstep over ROS: agents vs the bare exchange (`polymatch bench distributed`)")
    rows = []
    with tempfile.TemporaryDirectory() as workdir, domain_id() as dom:
        env = ros_environment(dom, base={k: v for k, v in os.environ.items()
                                         if k not in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE")})
        env["PYTHONUNBUFFERED"] = "1"
        for n in sizes:
            timeout = 60 + int(n * rounds / 20)
            log(f"bare exchange, {n} processes, {rounds} rounds")
            b_rates, b_matched, _ = _run_bare(n, rounds, args.executor, env, timeout)
            log(f"agents, {n} processes, {rounds} rounds")
            a_rates, a_matched, rc, wall, text = _run_agents(n, rounds, env, timeout, workdir)
            if rc not in (0, 3) or not a_rates:
                log(f"agents failed (exit {rc}): {text.strip().splitlines()[-1] if text.strip() else ''}")
            b = float(np.mean(b_rates)) if b_rates else float("nan")
            a = float(np.mean(a_rates)) if a_rates else float("nan")
            rows.append([n, f"{b:.1f}", f"{a:.1f}", f"{a / b:.0%}" if b_rates and a_rates else "-",
                         f"{max(b_matched):.2f}" if b_matched else "-",
                         f"{max(a_matched):.2f}" if a_matched else "-"])
    report.table(["processes", f"bare rounds/s ({args.executor})", "agents rounds/s", "agents / bare",
                  "bare: slowest match (s)", "agents: slowest match (s)"], rows,
                 caption=f"{rounds} lockstep rounds, all-to-all, one agent per process; rates are means over "
                         "processes; 'match' is the time from node creation until every peer's writer and reader "
                         "were matched (Fast DDS profile polymatch_ros/resources/fastdds_profile.xml)")
    report.text("- agents: congruent triangles, first-order model, rkmk4 (4 rounds per step), no monitor; "
                "a round = publish one stage message, take every peer's, run the stage's numerics.",
                "- bare: the same QoS (RELIABLE, VOLATILE, readers KEEP_ALL) and executor, no numerics.")
    return report
