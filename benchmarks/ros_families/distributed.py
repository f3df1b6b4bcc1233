"""Lockstep rounds per second over the ROS node set, against the bare transport's limit.

For N = 4, 8, 16, 32 processes on this machine, alternately (R repeats each, so
that the machine's drift hits both alike):

  bare     ``python -m benchmarks.ros_families.bare_exchange``: N processes exchanging one
           Float64MultiArray per round all-to-all with the agents' stage QoS, node and
           executor, no numerics — the transport's limit;
  typed    the same with the run's own typed message (polymatch_interfaces StageRows)
           carrying the same doubles: what the typed protocol costs against the untyped one;
  agents   N agent processes started directly (no runner, no monitor): congruent
           triangles, first-order model, rkmk4 (4 rounds per step), the same number of rounds;
  deployed the same through ``polymatch run`` with the monitor (what the demo runs); its
           rate against the agents' own shows what supervising a run costs.

Each process reports its own rounds/s and how long after its node was created
every peer was matched.  Every ROS process runs with loopback discovery, a domain
id reserved for the benchmark, and a timeout.
"""

import re
import sys
import tempfile
from dataclasses import dataclass, field

from .ros_runs import run_parallel

NAME = "distributed"
HELP = "lockstep rounds/s of the agent processes vs the bare rclpy exchange, N = 4 ... 32"


def add_arguments(p):
    from ..options import at_least, int_list
    p.add_argument("--agents", type=int_list(2), default=[4, 8, 16, 32], metavar="N,N,...",
                   help="numbers of processes (default 4,8,16,32)")
    p.add_argument("--rounds", type=at_least(8), default=400, help="rounds per run (default 400)")
    p.add_argument("--no-deployed", dest="deployed", action="store_false",
                   help="skip the runs through `polymatch run` with the monitor")


def _scene_yaml(n, steps, dt):
    return (f"name: bench_{n}\ndimension: 2\nseed: 1\nmodel: {{order: 1}}\n"
            f"integrator: {{method: rkmk4, dt: {dt}}}\ntime: {{t_end: {steps * dt!r}}}\n"
            f"groups:\n  - {{name: triangles, shape: triangle, count: {n}}}\n")


def _bare(n, rounds, env, timeout, message="untyped"):
    outs = run_parallel(
        [
            [
                sys.executable,
                "-m",
                "benchmarks.ros_families.bare_exchange",
                str(i),
                str(n),
                str(rounds),
                "--message",
                message,
            ]
            for i in range(n)
        ],
        env,
        timeout,
    )
    found = [re.search(r"([0-9.]+) rounds/s .* matched after ([0-9.]+) s", o) for o in outs]
    return [float(m.group(1)) for m in found if m], [float(m.group(2)) for m in found if m]


def _agents(n, path, env, timeout, run_id):
    from polymatch_ros.ros.config.configs import AgentConfig, ros_args

    argvs = [
        [sys.executable, "-m", "polymatch_ros.ros.nodes.agent", "--ros-args"]
        + ros_args(AgentConfig(scene=path, agent=i, run_id=run_id), node=f"agent_{i}")
        for i in range(n)
    ]
    return _parse_agents("\n".join(run_parallel(argvs, env, timeout)).splitlines())


def _parse_agents(lines):
    """(rounds/s, seconds until peers matched) of every agent's run record among ``lines``."""
    from polymatch_ros.ros.wire import run_records

    return _rates_and_matches(r for r in run_records(lines) if r.role == "agent" and r.finished)


def _rates_and_matches(records):
    """(rounds/s, seconds until peers matched) of finished agents' run ``records``."""
    records = list(records)
    return (
        [r.rounds_per_second for r in records],
        [r.matched_after for r in records if r.matched_after is not None],
    )


def _deployed(path, env, timeout, per_process, extra=(), with_matched=False):
    """(agent processes' rounds/s, failure or None[, seconds until peers matched])."""
    from .ros_runs import agent_records, run_cli

    records = path + ".records.jsonl"
    out = run_cli(env, ["run", path, "--no-compare", "--hold", "1e9", "--timeout",
                        str(timeout - 10), "-q", "--run-records", records, "-k", str(per_process),
                        *extra], timeout)
    rates, matched = _rates_and_matches(r for r in agent_records(records) if r.finished)
    errors = [line for line in out.stderr.splitlines() if line.startswith("polymatch: error:")]
    # 3: ran to t_end without matching yet (t_end is short here)
    failure = None if out.returncode in (0, 3) else (
        errors[-1] if errors else f"exit code {out.returncode}")
    return (rates, failure, matched) if with_matched else (rates, failure)


def _deployed_per_process(n):
    """Agents per process for the deployed run: 1 unless runner + monitor + n processes exceed
    the participants LOCALHOST discovery reaches (then what `polymatch run` itself would pick)."""
    from polymatch_ros.ros.supervisor.packing import fewest_agents_per_process

    return fewest_agents_per_process(n, own=2)


def _stats(values):
    import numpy as np

    return (max(values), float(np.median(values))) if values else (float("nan"), float("nan"))


def _mean_if_all(rates, expected):
    """The mean rate of a run in which all ``expected`` processes reported, else nan."""
    import numpy as np

    return np.mean(rates) if len(rates) == expected else float("nan")


def _finished(values):
    """The runs that finished (a failed run is nan)."""
    return [x for x in values if x == x]


@dataclass
class _SizeRuns:
    """The repeats at ``n`` processes: their scene file, the mean rate of every run and every
    peer-match time."""

    n: int
    rounds: int
    path: str
    bare: list = field(default_factory=list)
    typed: list = field(default_factory=list)
    agents: list = field(default_factory=list)
    deployed: list = field(default_factory=list)
    bare_match: list = field(default_factory=list)
    agents_match: list = field(default_factory=list)

    @property
    def timeout(self):
        return 60 + int(self.n * self.rounds / 10)


def _repeat(runs, r, env, deployed, failures):
    """Repeat ``r``: bare, agents and (if ``deployed``) deployed, one after the other."""
    n, timeout = runs.n, runs.timeout
    rates, matched = _bare(n, runs.rounds, env, timeout)
    runs.bare.append(_mean_if_all(rates, n))
    runs.bare_match += matched
    rates, _ = _bare(n, runs.rounds, env, timeout, "typed")
    runs.typed.append(_mean_if_all(rates, n))
    rates, matched = _agents(n, runs.path, env, timeout, 1000 + r)
    runs.agents.append(_mean_if_all(rates, n))
    runs.agents_match += matched
    if deployed:
        per_process = _deployed_per_process(n)
        rates, failure = _deployed(runs.path, env, timeout, per_process)
        runs.deployed.append(_mean_if_all(rates, -(-n // per_process)) if not failure
                             else float("nan"))
        if failure:
            failures.append(f"N = {n}, repeat {r + 1}, deployed: {failure}")


def _size_row(n, runs, repeats, deployed):
    bare, agents, dep = _finished(runs.bare), _finished(runs.agents), _finished(runs.deployed)
    (b_best, b_med), (a_best, a_med), (d_best, d_med) = _stats(bare), _stats(agents), _stats(dep)
    typed = _finished(runs.typed)
    t_med = _stats(typed)[1]
    return [
        n,
        f"{b_best:.1f} / {b_med:.1f}",
        f"{t_med / b_med:.0%}" if bare and typed else "-",
        f"{a_best:.1f} / {a_med:.1f}",
        f"{a_med / b_med:.0%}" if bare and agents else "-",
        f"{d_best:.1f} / {d_med:.1f}" if deployed else "-",
        f"{d_med / a_med:.0%}" if deployed and dep and agents else "-",
        f"{max(runs.bare_match):.2f}" if runs.bare_match else "-",
        f"{max(runs.agents_match):.2f}" if runs.agents_match else "-",
        f"{len(bare)}+{len(agents)}+{len(dep)} of {repeats}",
    ]


def _measure_size(n, rounds, repeats, deployed, workdir, env, log, failures):
    """The table row of ``n`` processes, from ``repeats`` alternating repeats."""
    from .ros_runs import write_scene

    path = write_scene(workdir, f"bench_{n}.yaml", _scene_yaml(n, max(1, rounds // 4), 0.01))
    runs = _SizeRuns(n, rounds, path)
    for r in range(repeats):
        log(f"N = {n}, repeat {r + 1}/{repeats}: bare, typed bare, agents"
            + (", deployed" if deployed else ""))
        _repeat(runs, r, env, deployed, failures)
    return _size_row(n, runs, repeats, deployed)


def _table(report, rows, rounds, repeats):
    report.table(
        [
            "processes",
            "bare rounds/s best / median",
            "typed / untyped bare (medians)",
            "agents rounds/s best / median",
            "agents / bare (medians)",
            "deployed (runner + monitor)",
            "deployed / agents (medians)",
            "bare: slowest match (s)",
            "agents: slowest match (s)",
            "runs that finished",
        ],
        rows,
        caption=f"{rounds} lockstep rounds, all-to-all, one agent per process, "
        f"{repeats} alternating repeats; rates are means over the processes of a run; 'match' "
        "is the time from node creation until every peer's writer and reader were matched",
    )


def _notes(report, sizes, deployed):
    report.text(
        "- agents: congruent triangles, first-order model, rkmk4 (4 rounds per step); a round = "
        "publish one stage message, take every peer's, run the stage's numerics; poses are "
        "published every step.",
        "- bare: the same QoS (RELIABLE, VOLATILE, readers KEEP_ALL), node and executor, "
        "no numerics.",
        "- deployed: `polymatch run` with the monitor, which hears every pose of every step "
        "and computes and publishes the metrics at most `report_rate` times a second (20 by "
        "default), on the same cores.",
    )
    packed = [n for n in sizes if _deployed_per_process(n) > 1]
    if packed and deployed:
        report.text(
            "- deployed at "
            + ", ".join(f"N = {n}: {_deployed_per_process(n)} agents per process "
                        f"({-(-n // _deployed_per_process(n))} processes)" for n in packed)
            + ": with the runner and the monitor, one process per agent would exceed the "
            "32 DDS participants that LOCALHOST discovery reaches (rmw_fastrtps probes 32 "
            "participant ports on 127.0.0.1); `polymatch run` picks this itself. Its rate is "
            "per process."
        )


def run(args, log):
    from domain_coordinator import domain_id

    from polymatch_ros.ros.network.environment import private_ros_environment

    from ..report import Report

    sizes = [4] if args.quick else args.agents
    rounds = 40 if args.quick else args.rounds
    repeats = 1 if args.quick else (args.repeats or 3)
    report = Report(
        NAME, "Lockstep over ROS: agents vs the bare exchange (`python -m benchmarks distributed`)"
    )
    rows, failures = [], []
    with tempfile.TemporaryDirectory() as workdir, domain_id() as dom:
        env = private_ros_environment(dom)
        for n in sizes:
            rows.append(_measure_size(n, rounds, repeats, args.deployed, workdir, env, log,
                                      failures))
    _table(report, rows, rounds, repeats)
    _notes(report, sizes, args.deployed)
    report.failures(failures)
    return report
