"""Lockstep at scale: `polymatch run` with its default packing, N = 8 ... 4096 agents.

For each N (congruent triangles, first-order model, rkmk4: 4 rounds a step, R rounds), a run
through `polymatch run` with the monitor, as a user starts it, with its default packing and
with the agents split over P processes (``--split``, default 4: the transport's cost), and
from its agents' run records (``--run-records``):

  rounds/s        the mean over the agent processes (after the first round);
  first round     seconds from the command's start until the last process completed its
                  first round: start-up, discovery and the lifecycle together;
  memory          the agent processes' peak resident memory (largest, MB);
  ms per round    the processes' mean split: publish (sending the stage message), wait
                  (until every peer's stage message of the round is taken: the transport and
                  the slowest peer), other (numerics, assembly, poses, run records);
  transport       (publish + wait) / all: the share of a round the transport takes.

The transport's share shows where the growth with N comes from: a complete graph's round
moves P (P - 1) block messages of K rows each (P processes of K agents), and each agent's
numerics are the mean field of (A-2), O(N) per process.
"""

import time

NAME = "scaling"
HELP = "lockstep at scale: rounds/s, start-up, memory, transport vs numerics, N = 8 ... 4096"


def add_arguments(p):
    from ..options import at_least, int_list
    p.add_argument("--agents", type=int_list(2), default=[8, 64, 256, 1024, 4096],
                   metavar="N,N,...", help="numbers of agents (default 8,64,256,1024,4096)")
    p.add_argument("--rounds", type=at_least(8), default=200, help="rounds per run (default 200)")
    p.add_argument("--split", type=at_least(2), default=4, metavar="P",
                   help="also run the agents in P processes (default 4)")


def _scene_yaml(n, steps, dt):
    return (f"name: scaling_{n}\ndimension: 2\nseed: 1\nmodel: {{order: 1}}\n"
            f"integrator: {{method: rkmk4, dt: {dt}}}\ntime: {{t_end: {steps * dt!r}}}\n"
            f"groups:\n  - {{name: triangles, shape: triangle, count: {n}}}\n")


def _measure(n, rounds, workdir, env, k=None):
    """One run of N agents, K a process (None: the default packing): (row of the table,
    failure or None)."""
    import numpy as np

    from .packing import _default_k
    from .ros_runs import agent_records, run_cli, write_scene

    path = write_scene(workdir, f"scaling_{n}.yaml", _scene_yaml(n, rounds // 4, 0.01))
    records, timeout = path + ".records.jsonl", 180 + n * rounds // 50
    started = time.time()
    asked = [] if k is None else ["-k", str(k)]
    out = run_cli(env, ["run", path, "--no-compare", "--hold", "1e9", "--timeout",
                        str(timeout - 10), "-q", "--run-records", records, *asked], timeout)
    wall = time.time() - started
    done = [r for r in agent_records(records) if r.finished]
    k = _default_k(n) if k is None else k
    errors = [line for line in out.stderr.splitlines() if line.startswith("polymatch: error:")]
    if out.returncode not in (0, 3) or not done:  # 3: ran to t_end without matching yet
        return [n, f"{-(-n // k)} x {k}"] + ["-"] * 6, (
            errors[-1] if errors else f"exit code {out.returncode}")
    split = {part: float(np.mean([r.ms_per_round.get(part, 0.0) for r in done]))
             for part in ("publish", "wait", "other")}
    first = max((r.first_round_at for r in done if r.first_round_at), default=started)
    transport = (split["publish"] + split["wait"]) / max(1e-12, sum(split.values()))
    return [n, f"{-(-n // k)} x {k}", f"{np.mean([r.rounds_per_second for r in done]):.1f}",
            f"{first - started:.1f}", f"{wall:.1f}", f"{max(r.max_rss_mb for r in done):.0f}",
            " / ".join(f"{split[p]:.2f}" for p in ("publish", "wait", "other")),
            f"{transport:.0%}"], None


def run(args, log):
    from ..report import Report
    from .ros_runs import private_runs

    sizes, rounds = ([8], 40) if args.quick else (args.agents, args.rounds)
    report = Report(NAME, "Lockstep at scale: the default packing (`python -m benchmarks "
                          "scaling`)")
    rows, failures = [], []
    with private_runs() as (workdir, env):
        for n in sizes:
            for k in (None, -(-n // args.split)):
                log(f"N = {n}, " + ("the default packing" if k is None else f"-k {k}"))
                row, failure = _measure(n, rounds, workdir, env, k)
                rows.append(row)
                if failure:
                    failures.append(f"N = {n}, -k {k or 'default'}: {failure}")
    report.table(["agents", "processes x agents each", "rounds/s", "first round after (s)",
                  "wall time (s)", "peak memory per process (MB)",
                  "ms per round: publish / wait / other", "transport share"], rows,
                 caption=f"{rounds} lockstep rounds (rkmk4: 4 a step) through `polymatch run` "
                         "with the monitor and its default agent nodes: the default packing, "
                         f"then the agents in {args.split} processes; one run each")
    report.failures(failures)
    return report
