"""Lockstep rounds per second of `polymatch run` by packing: N agents in P processes.

For each N (default 8, 32, 64, 256, 1024) and each number of processes P (default 1, 2, 4, 8,
16, 32; only those within the 32 DDS participants LOCALHOST discovery reaches, with the runner
and the monitor), one run of congruent triangles (first-order model, rkmk4, R rounds) through
`polymatch run -k ceil(N / P)` with the monitor, as users run it. Each agent process reports
its rounds/s in its run record; a run's rate is their mean. The table gives every packing's
rate, the best one, and the packing `polymatch run` picks without -k, with its rate against
the best: the measurement a default packing has to rest on.

A second table gives what every agent's own node costs (``agents.hosted``): at each size of
``--node-agents`` (default 64, 256, 1024), the default packing at each ``--agent-nodes``
level (full up to 256 agents), alternating, ``--repeats`` times each: the median rounds/s and
start-up (the slowest process's seconds from its start until its peers matched: the wall time
to its first round).
"""


NAME = "packing"
HELP = "lockstep rounds/s of `polymatch run` by packing: N agents in P processes"

PARTICIPANTS = 32  # rmw_fastrtps under LOCALHOST discovery probes 32 participant ports
OWN = 2            # the runner and the monitor


def add_arguments(p):
    from ..options import at_least, int_list
    p.add_argument("--agents", type=int_list(2), default=[8, 32, 64, 256, 1024],
                   metavar="N,N,...", help="ensemble sizes (default 8,32,64,256,1024)")
    p.add_argument("--processes", type=int_list(1), default=[1, 2, 4, 8, 16, 32],
                   metavar="P,P,...", help="numbers of agent processes (default 1,2,4,8,16,32)")
    p.add_argument("--rounds", type=at_least(8), default=200, help="rounds per run (default 200)")
    p.add_argument("--node-agents", type=int_list(2), default=[64, 256, 1024], metavar="N,N,...",
                   help="sizes of the agent-node cost table (default 64,256,1024)")


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


def _rate(path, env, timeout, k, extra=()):
    """(mean rounds/s of the run's agent processes, or nan; the failure; the slowest
    process's seconds until its peers matched, or nan)."""
    import numpy as np

    from .distributed import _deployed

    rates, failure, matched = _deployed(path, env, timeout, k, extra, with_matched=True)
    rate = float(np.mean(rates)) if rates and not failure else float("nan")
    return rate, failure, (max(matched) if matched and not failure else float("nan"))


def _default_k(n):
    """Agents per process of `polymatch run` in lockstep without -k (``choose_packing``)."""
    from polymatch_ros.ros.supervisor.packing import PackingAsked, choose_packing

    return choose_packing(PackingAsked(None, monitor=True), n, localhost=True).agents_per_process


#: --agent-nodes levels measured; full only up to this size (its start-up grows with the
#: square of a process's endpoints: minutes at 1024 agents a process)
LEVELS = ("full", "lean", "none")
FULL_UP_TO = 256


def _node_cost(sizes, repeats, rounds, workdir, env, log):
    """Rows of the agent-node cost table and its failures: the default packing with each
    --agent-nodes level, alternating; each level's median rounds/s and start-up."""
    import numpy as np

    from polymatch_ros.ros.supervisor.packing import agent_nodes

    from .ros_runs import write_scene

    rows, failures = [], []
    for n in sizes:
        path = write_scene(workdir, f"nodes_{n}.yaml", _scene_yaml(n, rounds // 4, 0.01))
        k = _default_k(n)
        levels = [lv for lv in LEVELS if lv != "full" or n <= FULL_UP_TO]
        runs = {lv: ([], []) for lv in levels}
        for r in range(repeats):
            for lv in levels:
                log(f"agent nodes, N = {n} (-k {k}), {lv}, repeat {r + 1}")
                rate, failure, start = _rate(path, env, 120 + n * rounds // 50, k,
                                             ("--agent-nodes", lv))
                runs[lv][0].append(rate)
                runs[lv][1].append(start)
                if failure:
                    failures.append(f"agent nodes, N = {n}, {lv}: {failure}")
        med = {lv: (float(np.median(rates)), float(np.median(starts)))
               for lv, (rates, starts) in runs.items()}
        auto = agent_nodes("auto", k)
        rows.append([n, f"{-(-n // k)} x {k}", auto, _by_level(med, 0, ".1f"),
                     _by_level(med, 1, ".2f"),
                     f"{med[auto][0] / med['none'][0]:.0%}" if auto in med else "-"])
    return rows, failures


def _by_level(med, i, fmt):
    """'full 1.0; lean 2.0; none 3.0': figure ``i`` of each level measured ('-' if not)."""
    return "; ".join(f"{lv} {med[lv][i]:{fmt}}" if lv in med else f"{lv} -" for lv in LEVELS)


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
    from ..report import Report
    from .ros_runs import private_runs, write_scene

    sizes = [8] if args.quick else args.agents
    processes = [1, 2] if args.quick else args.processes
    rounds = 40 if args.quick else args.rounds
    report = Report(NAME, "Lockstep by packing: N agents in P processes "
                          "(`python -m benchmarks packing`)")
    rows, failures = [], []
    with private_runs() as (workdir, env):
        for n in sizes:
            path = write_scene(workdir, f"packing_{n}.yaml", _scene_yaml(n, rounds // 4, 0.01))
            measured = {}
            for p, k in packings(n, processes):
                log(f"N = {n}: {p} processes of {k}")
                measured[(p, k)], failure, _ = _rate(path, env, 120 + n * rounds // 50, k)
                if failure:
                    failures.append(f"N = {n}, -k {k}: {failure}")
            rows.append(_row(n, measured, _default_k(n)))
        node_rows, node_failures = _node_cost(
            [8] if args.quick else args.node_agents, 1 if args.quick else (args.repeats or 2),
            rounds, workdir, env, log)
    report.table(["agents", "processes x agents each: rounds/s", "fastest", "default (no -k)",
                  "default / fastest"], rows,
                 caption=f"{rounds} lockstep rounds (rkmk4: 4 a step) through `polymatch run` "
                         "with the monitor; a run's rate is the mean over its agent processes")
    report.table(["agents", "default packing", "auto", "rounds/s by --agent-nodes",
                  "start-up s by --agent-nodes", "auto / none rounds/s"], node_rows,
                 caption="Every agent a node (`agents.hosted`): the default packing at each "
                         "`--agent-nodes` level, medians of alternating runs; start-up: the "
                         "slowest process's seconds from its start until its peers matched")
    report.failures(failures + node_failures)
    return report
