"""Deployed lockstep rounds per second on communication graphs, and past 32 participants.

For each number of agents N and each packing (agents per process), ``polymatch run`` (runner,
monitor, agents; lockstep, rkmk4, congruent triangles, first order) runs the same scene on
the complete graph, a ring (k = 1) and a k-nearest graph (k = 4), alternately R times so the
machine's drift hits every graph alike.  On a graph an agent subscribes to, and waits for,
its in-neighbours only, so the exchange should profit from sparsity; the ratio column is the
graph's median rounds/s over the complete graph's at the same N and packing.

Runs whose processes (with the runner and the monitor) exceed the 32 participants that
LOCALHOST discovery reaches use ``--discovery server``: the run's own Fast DDS discovery
server on 127.0.0.1.  Every ROS process runs with a domain id reserved for the benchmark and
a timeout.
"""

import os
import tempfile

NAME = "graphs"
HELP = "deployed lockstep rounds/s on complete, ring and k-nearest graphs; N past 32 (server)"
GRAPHS = ("complete", "ring", "k_nearest")


def _graph_yaml(graph, n):
    """The scene's graph key: a ring of 1, or each agent's 4 nearest (fewer when N is small)."""
    return {"complete": "complete", "ring": "{ring: 1}",
            "k_nearest": f"{{k_nearest: {min(4, n - 1)}}}"}[graph]


def add_arguments(p):
    from ..options import at_least, int_list

    p.add_argument("--agents", type=int_list(2), default=[8, 32], metavar="N,N,...",
                   help="numbers of agents (default 8,32)")
    p.add_argument("--per-process", type=int_list(1), default=[1], metavar="K,K,...",
                   help="agents per process, each packing measured (default 1)")
    p.add_argument("--rounds", type=at_least(8), default=200,
                   help="lockstep rounds per run (default 200)")


def _scene_yaml(n, graph, steps, dt):
    return (f"name: graph_bench_{n}\ndimension: 2\nseed: 1\nmodel: {{order: 1}}\n"
            f"graph: {graph}\nintegrator: {{method: rkmk4, dt: {dt}}}\n"
            f"time: {{t_end: {steps * dt!r}}}\n"
            f"groups:\n  - {{name: triangles, shape: triangle, count: {n}}}\n")


def _discovery(n, per_process):
    """localhost while runner + monitor + the agent processes fit its 32 participants."""
    from polymatch_ros.ros.supervisor.packing import LOCALHOST_PARTICIPANTS

    return "localhost" if 2 + -(-n // per_process) <= LOCALHOST_PARTICIPANTS else "server"


def _median(values):
    import numpy as np

    return float(np.median(values)) if values else float("nan")


def _measure(n, per_process, rounds, repeats, workdir, env, log, failures):
    """{graph: (median rounds/s, slowest match s)} for one N and packing."""
    from .distributed import _deployed
    from .ros_runs import write_scene

    discovery = _discovery(n, per_process)
    paths = {graph: write_scene(workdir, f"{graph}_{n}.yaml",
                                _scene_yaml(n, _graph_yaml(graph, n), max(1, rounds // 4), 0.01))
             for graph in GRAPHS}
    rates = {graph: [] for graph in GRAPHS}
    matched = {graph: [] for graph in GRAPHS}
    timeout = 120 + int(n * rounds / 10)
    for r in range(repeats):
        for graph in GRAPHS:
            log(f"N = {n}, {per_process} per process, {graph}, repeat {r + 1}/{repeats}")
            got, failure, waits = _deployed(paths[graph], env, timeout, per_process,
                                            ["--discovery", discovery], with_matched=True)
            if failure:
                failures.append(f"N = {n}, k = {per_process}, {graph}: {failure}")
            elif got:
                rates[graph].append(sum(got) / len(got))
                matched[graph] += waits
    return discovery, {g: (_median(rates[g]), max(matched[g], default=float("nan")))
                       for g in GRAPHS}


def run(args, log):
    from domain_coordinator import domain_id

    from polymatch_ros.ros.network.environment import ros_environment

    from ..report import Report

    sizes = [4] if args.quick else args.agents
    rounds = 24 if args.quick else args.rounds
    repeats = 1 if args.quick else (args.repeats or 2)
    report = Report(NAME, "Lockstep on communication graphs (`python -m benchmarks graphs`)")
    rows, failures = [], []
    with tempfile.TemporaryDirectory() as workdir, domain_id() as dom:
        env = ros_environment(dom, base={k: v for k, v in os.environ.items()
                                         if k not in ("ROS_DOMAIN_ID",
                                                      "ROS_AUTOMATIC_DISCOVERY_RANGE")})
        for n in sizes:
            for per_process in args.per_process:
                discovery, found = _measure(n, per_process, rounds, repeats, workdir, env,
                                            log, failures)
                base = found["complete"][0]
                for graph, (rate, wait) in found.items():
                    rows.append([n, per_process, discovery, graph, f"{rate:.1f}",
                                 f"{rate / base:.2f}" if base == base else "-",
                                 f"{wait:.1f}"])
    report.table(["agents", "per process", "discovery", "graph", "rounds/s (median)",
                  "vs complete", "slowest match (s)"], rows,
                 caption=f"{rounds} lockstep rounds through `polymatch run` (runner + monitor), "
                 f"{repeats} alternating repeats; rates are means over the agent processes")
    report.failures(failures)
    return report
