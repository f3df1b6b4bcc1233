"""One ensemble on three hosts over a lossy, late network (network namespaces on one machine).

Three hosts are Linux network namespaces on a private bridge (benchmarks/hosts/namespaces.py);
each runs `polymatch run SCENE --only RANGE --discovery subnet` (the last one with the
monitor), data over UDPv4.  Loss: nftables in every host drops that share of what it
receives (``numgen random``); delay: the agents' ``--delay`` (realtime).

  realtime  congruent triangles (A-2), 12 agents 4/4/4, 20 steps/s, time scale 3: the matching
            diameter and the simulated time from which it stays under the scene's tolerance
            (monitor reports read from its status topic inside the lead host), against loss
            and delay; the centralised run with the same step is the reference (Thm 4.2);
  lockstep  triangles and tetrahedra (F-2), 12 agents 4/4/4: rounds/s under loss (RELIABLE
            retransmission) and the max vertex deviation of the saved poses from the
            centralised run with the same integrator and step.

Every ROS process runs inside the namespaces; tcpdump on the root namespace's interfaces
counts DDS packets (reported; it must be 0), with the bridge as the control.  Every process is
bounded by a timeout and ended by PID; the namespaces are deleted afterwards, also on failure
and Ctrl-C.  Needs root, iproute2, nftables and tcpdump.
"""

import os
import signal
import sys
import tempfile
import time
from dataclasses import dataclass, field

import numpy as np

NAME = "lossy"
HELP = "3 namespace hosts: realtime error vs loss and delay, lockstep rounds/s vs loss"

REALTIME_SCENE, LOCKSTEP_SCENE = "congruent_triangles", "mixed_triangles_tetrahedra"
RATE, TIME_SCALE, PEER_TIMEOUT = 20.0, 3.0, 1.0
HOSTS = 3


def _percents(text):
    """'0,10,20' -> [0, 10, 20]: whole percents in 0..99 (nftables draws integers)."""
    import argparse

    from ..options import int_list

    values = int_list(0)(text)
    if max(values) > 99:
        raise argparse.ArgumentTypeError(f"loss percents must be in 0..99, got {max(values)}")
    return values


def add_arguments(p):
    from ..options import at_least, float_list

    p.add_argument("--loss", type=_percents, default=[0, 5, 10, 20, 40], metavar="P,...",
                   help="realtime: percent of packets every host drops (default 0,5,10,20,40)")
    p.add_argument("--delay", type=float_list(0.0), default=[0.0, 0.05, 0.2], metavar="S,...",
                   help="realtime: injected delay in s (default 0,0.05,0.2)")
    p.add_argument("--lockstep-loss", type=_percents, default=[0, 10, 20],
                   metavar="P,...", help="lockstep: loss percents (default 0,10,20)")
    p.add_argument("--t-end", type=at_least(1.0, float), default=60.0,
                   help="realtime: simulated seconds before a run that has not matched ends "
                   "(default 60)")


def _sizes(args):
    """(realtime agents, lockstep agents per group, lockstep t_end, realtime t_end)."""
    if args.quick:
        return 3, 3, 0.1, 6.0
    return 12, 6, 1.0, args.t_end


def _lossy(net, percent):
    """Every host drops ``percent``% of what it receives (none: the rules are removed)."""
    for index in range(HOSTS):
        net.remove_loss(index)
        if percent > 0:
            net.add_loss(index, percent=percent)


def _records(path):
    from polymatch_ros.ros.wire import run_records

    if not os.path.exists(path):
        return []
    with open(path, encoding="utf-8") as fh:
        return run_records(fh)


def _echo_status(net, seconds):
    """``during``: `polymatch echo` of the status topic inside the lead host while the hosts
    run; returns (the echo process, the packets the loss rules dropped)."""
    from polymatch_ros.ros.network import discovery

    def observe(procs, started, env):
        echo_env = discovery.discovery_environments("subnet").for_role("client", env)
        echo = procs.start([sys.executable, "-m", "polymatch_ros.cli", "echo",
                            "/polymatch/status", "--json", "--timeout", str(seconds)], echo_env,
                           seconds + 10, "echo", prefix=net.prefix(HOSTS - 1))
        for proc in started:
            proc.wait(timeout=seconds + 10)
        return echo, sum(net.dropped(i) for i in range(HOSTS))

    return observe


def _status_records(echo):
    """The monitor's run records among those `polymatch echo` printed (the agents publish
    theirs on the status topic too)."""
    from polymatch_ros.ros.wire import echoed_run_records

    from ..hosts.runs import Processes

    lines = Processes.output(echo).splitlines()
    records = echoed_run_records(lines)
    return [r for r in records if r.role == "monitor"]


def _on_hosts(net, directory, argvs, during, seconds, captures):
    """run_on_hosts with the bridge as control; adds the DDS packet counts to ``captures``."""
    from ..hosts.namespaces import Capture
    from ..hosts.runs import run_on_hosts

    with Capture(directory, ["br0"], net.bridge, "bridge") as bridge:
        started, texts, root, found = run_on_hosts(net, directory, argvs, during, seconds)
    captures["root"] += root.matched()
    captures["bridge"] += bridge.matched()
    return started, texts, found


def _realtime_cell(net, scene_file, n, t_end, loss, delay, captures):
    from ..hosts.runs import host_argv

    k, seconds = n // HOSTS, int(t_end / TIME_SCALE) + 60
    _lossy(net, loss)
    with tempfile.TemporaryDirectory(prefix="polymatch_lossy_") as directory:
        argvs = [host_argv(scene_file, f"{k * i}-{k * i + k - 1}", i == HOSTS - 1,
                           "--mode", "realtime", "--rate", RATE, "--time-scale", TIME_SCALE,
                           "--t-end", t_end, "-k", k, "--peer-timeout", PEER_TIMEOUT,
                           "--delay", delay,
                           "--run-records", os.path.join(directory, f"h{i}.jsonl"),
                           timeout=seconds - 10)
                 for i in range(HOSTS)]
        started, texts, (echo, dropped) = _on_hosts(
            net, directory, argvs, _echo_status(net, seconds), seconds, captures)
        agents = [r for i in range(HOSTS) for r in _records(os.path.join(directory, f"h{i}.jsonl"))
                  if r.role == "agent"]
        lead = started[-1].returncode
        failure = "" if lead in (0, 3) else f"lead host exit {lead}: {_last_error(texts[-1])}"
        return RealtimeCell(loss, delay, lead, _status_records(echo), agents, dropped, failure)


def _last_error(text):
    errors = [line for line in text.splitlines() if line.startswith("polymatch: error:")]
    return errors[-1] if errors else "no error line"


def _lockstep_cell(net, scene, scene_file, n, t_end, loss, captures):
    from ..hosts.runs import host_argv, lockstep_split

    seconds = 150
    _lossy(net, loss)
    with tempfile.TemporaryDirectory(prefix="polymatch_lossy_") as directory:
        out = os.path.join(directory, "final.npz")
        argvs = [host_argv(scene_file, only, i == HOSTS - 1, "--t-end", t_end, "-k", n // HOSTS,
                           "--run-records", os.path.join(directory, f"h{i}.jsonl"),
                           *(["--save", out] if i == HOSTS - 1 else []), timeout=seconds - 10)
                 for i, only in enumerate(lockstep_split(HOSTS, n))]
        began = time.monotonic()

        def dropped(procs, started, env):
            for proc in started:
                proc.wait(timeout=seconds + 10)
            return sum(net.dropped(i) for i in range(HOSTS))

        started, texts, lost = _on_hosts(net, directory, argvs, dropped, seconds, captures)
        wall = time.monotonic() - began
        agents = [r for i in range(HOSTS) for r in _records(os.path.join(directory, f"h{i}.jsonl"))
                  if r.role == "agent"]
        codes = [p.returncode for p in started]
        if any(c not in (0, 3) for c in codes) or not os.path.exists(out):
            return LockstepCell(loss, agents, None, lost, wall,
                                f"exit codes {codes}: {_last_error(texts[-1])}")
        return LockstepCell(loss, agents, central_deviation(scene, out), lost, wall)


def _central_time(scene, t_end):
    """The centralised run's time to tolerance with the realtime step h = time scale / rate."""
    from dataclasses import replace

    from polymatch_ros.core.stepping.simulate import choose_numerics, simulate

    dt = TIME_SCALE / RATE
    method = choose_numerics(scene, None, dt, distributed=True).name
    traj = simulate(replace(scene, t_end=t_end), method, dt, keep_states=False,
                    stop_when_converged=True)
    return traj.converged_at


def _interruptible():
    """SIGTERM ends the run like Ctrl-C (so the namespaces are deleted); returns the old
    handler."""
    def stop(signum, frame):
        raise KeyboardInterrupt

    return signal.signal(signal.SIGTERM, stop)


def _measure(args, log, net, workdir, captures):
    """(realtime cells, lockstep cells) over the hosts ``net``."""
    from polymatch_ros.core.scenes.scene import load_scene

    from ..hosts.runs import scene_with

    n_rt, per_group, lock_t_end, rt_t_end = _sizes(args)
    losses = [0] if args.quick else args.loss
    delays = [0.05] if args.quick else args.delay
    lock_losses = [10] if args.quick else args.lockstep_loss
    rt_file = scene_with(workdir, REALTIME_SCENE, n_rt)
    realtime = []
    for delay in delays:
        for loss in losses:
            log(f"realtime: {loss:g} % loss, {delay:g} s delay")
            realtime.append(_realtime_cell(net, rt_file, n_rt, rt_t_end, loss, delay, captures))
    lock_file = scene_with(workdir, LOCKSTEP_SCENE, per_group)
    lock_scene = load_scene(lock_file)
    n_lock = lock_scene.model.n_agents
    lockstep = []
    for loss in lock_losses:
        log(f"lockstep: {loss:g} % loss")
        lockstep.append(_lockstep_cell(net, lock_scene, lock_file, n_lock, lock_t_end, loss,
                                       captures))
    return realtime, lockstep, (rt_file, n_rt, rt_t_end), (n_lock, lock_t_end)


def run(args, log):
    from polymatch_ros.core.scenes.scene import load_scene

    from ..hosts.namespaces import NetnsHosts, unavailable_reason
    from ..report import Report

    report = Report(NAME, "Three hosts over a lossy, late network (`python -m benchmarks lossy`)")
    reason = unavailable_reason(("nft", "tcpdump"))
    if reason:
        report.text(f"Not run: {reason}.")
        return report
    captures = {"root": 0, "bridge": 0}
    old = _interruptible()
    try:
        with tempfile.TemporaryDirectory(prefix="polymatch_lossy_") as workdir, \
                NetnsHosts(HOSTS) as net:
            realtime, lockstep, (rt_file, n_rt, rt_t_end), (n_lock, lock_t_end) = _measure(
                args, log, net, workdir, captures)
            rt_scene = load_scene(rt_file)
            central = _central_time(rt_scene, rt_t_end)
        left = net.left_over()
    finally:
        signal.signal(signal.SIGTERM, old)
    rows = [realtime_row(c, n_rt, rt_scene.tolerance, central) for c in realtime]
    report.table(REALTIME_HEADER, rows, caption=(
        f"realtime, {n_rt} agents ({n_rt // HOSTS} per host), {RATE:g} steps/s, time scale "
        f"{TIME_SCALE:g} (h = {TIME_SCALE / RATE:g}), tolerance {rt_scene.tolerance:g}, "
        f"t_end {rt_t_end:g}; centralised run with the same h: tolerance from t = "
        + ("-" if central is None else f"{central:.2f}")))
    report.table(LOCKSTEP_HEADER, lockstep_rows(lockstep), caption=(
        f"lockstep, {n_lock} agents ({n_lock // HOSTS} per host), t_end {lock_t_end:g}"))
    report.text(
        "- loss: every host drops that share of the packets it receives (nftables); "
        "'packets dropped' counts them over the three hosts.",
        f"- DDS packets on the root namespace's interfaces during all runs: {captures['root']} "
        f"(control: {captures['bridge']} on the hosts' bridge); namespaces left over: "
        f"{len(left)}.")
    return report


# -- tables from the run records (no namespaces needed) -------------------------------------

REALTIME_HEADER = ["loss %", "delay s", "converged", "time to tolerance (sim. s)",
                   "vs centralised", "final diameter", "late ticks", "packets dropped"]
LOCKSTEP_HEADER = ["loss %", "rounds/s per agent (mean)", "vs 0 % loss",
                   "max vertex deviation from centralised", "packets dropped", "wall s"]


@dataclass
class RealtimeCell:
    """One realtime run: its settings and what the records say."""

    loss: float
    delay: float
    exit_code: int
    monitor: list = field(default_factory=list)     # the monitor's status records, in order
    agents: list = field(default_factory=list)      # the agents' final records (every host)
    dropped: int = 0                                # packets the loss rules dropped
    failure: str = ""


@dataclass
class LockstepCell:
    loss: float
    agents: list = field(default_factory=list)
    deviation: float = None
    dropped: int = 0
    wall: float = 0.0
    failure: str = ""


def time_to_tolerance(records, n_agents, tolerance):
    """The simulated time from which every monitor report of all ``n_agents`` stayed under
    ``tolerance`` (None if the last such report is not under it)."""
    full = [r for r in records if r.agents_heard == n_agents and r.diameter is not None]
    if not full or not full[-1].diameter < tolerance:
        return None
    first = len(full) - 1
    while first > 0 and full[first - 1].diameter < tolerance:
        first -= 1
    return full[first].t


def final_diameter(records, n_agents):
    """The diameter of the last monitor report that heard all ``n_agents`` (None if none)."""
    full = [r for r in records if r.agents_heard == n_agents and r.diameter is not None]
    return full[-1].diameter if full else None


def realtime_row(cell, n_agents, tolerance, central_time):
    """A row of REALTIME_HEADER; ``central_time``: the centralised run's time to tolerance."""
    if cell.failure:
        return [f"{cell.loss:g}", f"{cell.delay:g}", f"failed: {cell.failure}"] + ["-"] * 5
    reached = time_to_tolerance(cell.monitor, n_agents, tolerance)
    diameter = final_diameter(cell.monitor, n_agents)
    converged = cell.exit_code == 0 and reached is not None
    late = sum(r.late_ticks for r in cell.agents)
    ticks = sum(r.steps for r in cell.agents)
    return [f"{cell.loss:g}", f"{cell.delay:g}", "yes" if converged else "no",
            f"{reached:.2f}" if converged else "not reached",
            f"{reached / central_time:.2f}x" if converged and central_time else "-",
            "-" if diameter is None else f"{diameter:.2e}",
            f"{late} of {ticks}" if ticks else "-", str(cell.dropped)]


def mean_rate(cell):
    rates = [r.rounds_per_second for r in cell.agents if r.role == "agent" and r.finished]
    return float(np.mean(rates)) if rates else None


def lockstep_rows(cells):
    """Rows of LOCKSTEP_HEADER; the rate ratio is against the cell with 0 % loss (if any)."""
    base = next((mean_rate(c) for c in cells if c.loss == 0 and not c.failure), None)
    rows = []
    for cell in cells:
        rate = None if cell.failure else mean_rate(cell)
        if rate is None:
            rows.append([f"{cell.loss:g}", f"failed: {cell.failure or 'no agent records'}"]
                        + ["-"] * 4)
            continue
        rows.append([f"{cell.loss:g}", f"{rate:.1f}",
                     f"{rate / base:.2f}" if base else "-",
                     "-" if cell.deviation is None else f"{cell.deviation:.1e}",
                     str(cell.dropped), f"{cell.wall:.1f}"])
    return rows


def saved_vertices(scene, path):
    """(t, [vertices of group g: (n_g, n_a, d)]) of the final poses a run saved (--save)."""
    from polymatch_ros.core.metrics import vertices
    from polymatch_ros.core.saved import load_saved

    saved = load_saved(path)
    out = [vertices(sg.centroids[-1], sg.rotations[-1], g.reference)
           for g, sg in zip(scene.model.groups, saved.groups)]
    return saved.t, out


def central_deviation(scene, path):
    """Max vertex deviation of the saved final poses from the centralised simulation with the
    same integrator and step, run here to the same t (lockstep equals it to round-off)."""
    from dataclasses import replace

    from polymatch_ros.core.metrics import vertices
    from polymatch_ros.core.stepping.simulate import choose_numerics, simulate

    t, got = saved_vertices(scene, path)
    method = choose_numerics(scene, None, None, distributed=True).name
    sc = replace(scene, t_end=t)
    traj = simulate(sc, method, sc.integrator.dt, samples=[t], metrics=False)
    model = traj.scene.model            # the representation the simulation ran in
    want = [vertices(gs.x + scene.origin, model.rotations.to_matrices(gs.rot), g.reference)
            for g, gs in zip(model.groups, traj.final.groups)]
    return max(float(np.max(np.linalg.norm(a - b, axis=-1))) for a, b in zip(got, want))
