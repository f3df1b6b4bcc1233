"""Lockstep rounds per second of `polymatch run` by packing: N agents in P processes.

For each N (default 8, 32, 64, 256, 1024) and each number of processes P (default 1, 2, 4, 8,
16, 32; only those within the 32 DDS participants LOCALHOST discovery reaches, with the runner
and the monitor), one run of congruent triangles (first-order model, rkmk4, R rounds) through
`polymatch run -k ceil(N / P)` with the monitor, as users run it. Each agent process reports
its rounds/s in its run record; a run's rate is their mean. The table gives every packing's
rate, the best one, and the packing `polymatch run` picks without -k, with its rate against
the best: the measurement a default packing has to rest on.
"""

import tempfile

NAME = "packing"
HELP = "lockstep rounds/s of `polymatch run` by packing: N agents in P processes"

PARTICIPANTS = 32  # rmw_fastrtps under LOCALHOST discovery probes 32 participant ports
OWN = 2            # the runner and the monitor


def add_arguments(p):
    from .options import at_least, int_list
    p.add_argument("--agents", type=int_list(2), default=[8, 32, 64, 256, 1024],
                   metavar="N,N,...", help="ensemble sizes (default 8,32,64,256,1024)")
    p.add_argument("--processes", type=int_list(1), default=[1, 2, 4, 8, 16, 32],
                   metavar="P,P,...", help="numbers of agent processes (default 1,2,4,8,16,32)")
    p.add_argument("--rounds", type=at_least(8), default=200, help="rounds per run (default 200)")


def _scene_yaml(n, steps, dt):
    return (f"name: packing_{n}\ndimension: 2\nseed: 1\nmodel: {{order: 1}}\n"
            f"integrator: {{method: rkmk4, dt: {dt}}}\ntime: {{t_end: {steps * dt!r}}}\n"
            f"groups:\n  - {{name: triangles, shape: triangle, count: {n}}}\n")


def packings(n, processes):
    """(P, agents per process) for each asked P that fits: P <= n, and the processes that
    -k ceil(n / P) makes stay within the participant limit."""
    out = []
    for p in processes:
        k = -(-n // p)
        made = -(-n // k)
        if p <= n and made + OWN <= PARTICIPANTS and (made, k) not in out:
            out.append((made, k))
    return out


def _rate(path, env, timeout, k):
    """Mean rounds/s of the run's agent processes, or (nan, the failure)."""
    import numpy as np

    from .distributed import _deployed

    rates, failure = _deployed(path, env, timeout, k)
    return (float(np.mean(rates)) if rates and not failure else float("nan")), failure


def _row(n, measured, default_k):
    """One table row: each packing's rate, the best, and the default's share of it."""
    finished = {pk: r for pk, r in measured.items() if r == r}
    best = max(finished, key=finished.get, default=None)
    shown = "; ".join(f"{p} x {k}: {rate:.1f}" if rate == rate else f"{p} x {k}: failed"
                      for (p, k), rate in measured.items())
    default = next(((p, k) for (p, k) in measured if k == default_k), None)
    share = (f"{finished[default] / finished[best]:.0%}"
             if best and default in finished else "-")
    return [n, shown, f"{best[0]} x {best[1]}" if best else "-",
            f"{-(-n // default_k)} x {default_k}", share]


def run(args, log):
    from domain_coordinator import domain_id

    from polymatch_ros.ros.supervisor.children import fewest_agents_per_process
    from polymatch_ros.ros.supervisor.environment import private_ros_environment

    from .report import Report
    from .ros_runs import write_scene

    sizes = [8] if args.quick else args.agents
    processes = [1, 2] if args.quick else args.processes
    rounds = 40 if args.quick else args.rounds
    report = Report(NAME, "Lockstep by packing: N agents in P processes "
                          "(`python -m benchmarks packing`)")
    rows, failures = [], []
    with tempfile.TemporaryDirectory() as workdir, domain_id() as dom:
        env = private_ros_environment(dom)
        for n in sizes:
            path = write_scene(workdir, f"packing_{n}.yaml", _scene_yaml(n, rounds // 4, 0.01))
            default_k = max(1, fewest_agents_per_process(n, OWN))
            measured = {}
            for p, k in packings(n, processes):
                log(f"N = {n}: {p} processes of {k}")
                measured[(p, k)], failure = _rate(path, env, 120 + n * rounds // 50, k)
                if failure:
                    failures.append(f"N = {n}, -k {k}: {failure}")
            rows.append(_row(n, measured, default_k))
    report.table(["agents", "processes x agents each: rounds/s", "fastest", "default (no -k)",
                  "default / fastest"], rows,
                 caption=f"{rounds} lockstep rounds (rkmk4: 4 a step) through `polymatch run` "
                         "with the monitor; a run's rate is the mean over its agent processes")
    report.failures(failures)
    return report
