"""`polymatch run SCENE`: a whole distributed ensemble from one scene file, without launch.

Starts the monitor and one process per agent (or per K agents) in the ensemble's namespace
(``-r __ns:=/<ensemble>``, nodes ``agent_<i>`` and ``monitor``), all with loopback discovery
unless the user set otherwise, in the user's ROS domain (``--isolated``: a fresh one); shows
progress (simulated time, diameter, rounds/s); stops at t_end or once the diameter has stayed
under the scene's tolerance; prints a summary (final diameters per group, in lockstep the
deviation from the centralised solution, wall time, rounds/s) from the agents' final poses and
run records; and ends every process it started, by PID, also on Ctrl-C and when a child dies.
"""

from __future__ import annotations

import hashlib
import os
import random
import signal
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from types import FrameType
from typing import Any

from ...console import Progress
from ...core.errors import PolymatchError
from .. import wire
from ..config.configs import AgentConfig, MonitorConfig, ros_args
from ..network.discovery import (
    DISCOVERY_VARIABLES,
    DiscoveryEnvironments,
    DiscoveryServer,
    discovery_environments,
    start_discovery_server,
)
from ..network.environment import (
    describe_domain,
    domain_reserved,
    ros_environment,
    run_domain_id,
)
from ..process import forked
from ..process.teardown import teardown_watchdog
from ..wire.checkpoint import Checkpoint, CheckpointFile
from . import bridge_run
from .children import Child, describe_agents, partition, stop_all
from .plan import RunPlan
from .recorder_child import report_recording, start_recorder
from .run_loop import REMOTE_FINAL_POSE_SECONDS, Supervision
from .shm import ShmSweep
from .summary import RunOutcome, report, verdict
from .watcher import Watcher


@dataclass(frozen=True)
class RunContext:
    """A run as it starts on this host: its plan, the ROS environment and domain of its
    processes and the discovery environments (None for LOCALHOST)."""

    plan: RunPlan
    env: dict[str, str]                   # every process's environment (LOCALHOST discovery)
    domain: int                           # ROS_DOMAIN_ID
    envs: DiscoveryEnvironments | None    # client/super-client/server overlays, --discovery
    shared_domain: bool                   # the user's domain, or discovery beyond loopback
    directory: str                        # the run's private temporary directory
    run_id: int                           # the stage messages' and checkpoints' run id

    @property
    def agents_per_process(self) -> int:
        return self.plan.packing.agents_per_process

    @property
    def exchange_blocks(self) -> int | None:
        """K where the agents send their states a block of K at a time (packed lockstep and
        realtime processes)."""
        k = self.agents_per_process
        return k if k > 1 and self.plan.mode.packs else None

    def checkpoint_path(self, name: str) -> str:
        """The checkpoint of the agent process ``name`` (a bridge agent's holds the measured
        pose it relayed last: for ``--save`` of a run that ends early; restarted, it takes its
        robot's pose)."""
        return os.path.join(self.directory, name + ".checkpoint")

    def checkpoints(self, children: Sequence[Child]) -> list[tuple[tuple[int, ...],
                                                                   Checkpoint | None]]:
        """Each agent process's agents and last checkpoint (None: none)."""
        return [(c.agents, CheckpointFile(self.checkpoint_path(c.name), self.run_id).read())
                for c in children]

    def role_env(self, role: str) -> dict[str, str]:
        """The environment of a process in ``role`` ("client": agents and robots,
        "super_client": monitor and recorder) under the run's discovery; LOCALHOST: ``env``."""
        return self.env if self.envs is None else self.envs.for_role(role, self.env)



def run(plan: RunPlan) -> int:
    """Start, watch and end this host's processes of ``plan``; the run's exit code.

    The caller ends the process with it (``teardown.end_process``): rclpy ran in this process.
    """
    # a domain reserved for this run (--isolated, or by its caller: ``domain_reserved``) holds
    # no other ensemble; the user's, or one reached beyond loopback, may
    # (``Watcher.refuse_names_in_use``)
    isolated = plan.hosts.isolated
    with run_domain_id(isolated) as domain, tempfile.TemporaryDirectory(
        prefix="polymatch_run_"
    ) as directory, forked.fork_server(directory, also=_preloaded_for(plan)):
        shared = (not (isolated or domain_reserved(domain))
                  or plan.hosts.discovery.kind != "localhost")
        env = ros_environment(domain)
        spec = plan.hosts.discovery
        envs = None if spec.kind == "localhost" else discovery_environments(spec, directory)
        sweep = ShmSweep()  # /dev/shm as the run found it
        context = RunContext(plan, env, domain, envs, shared, directory, _run_id(plan))
        _adopt(env if envs is None else envs.for_role("super_client", env))
        server = _start_server(context, directory)
        try:
            code = _run(context, server)
        finally:
            if server is not None:
                server.stop()  # the one running now (``recovery`` may have restarted it)
            sweep.remove_dead()  # what its ended (or killed) children left in /dev/shm
    return code


def _preloaded_for(plan: RunPlan) -> tuple[str, ...]:
    """What the fork server imports for this run beyond its own list: a bridge run's robots,
    one per agent, each turn poses with scipy's rotations (``nodes.robot``)."""
    robots = len(plan.hosts.agents) if plan.bridge is not None else 0
    return ("scipy.spatial.transform",) if robots > 1 else ()


# How long a run in a shared domain listens to the ROS graph before it starts any process
# (loopback discovery answers within a few hundred milliseconds)
GRAPH_LISTEN_SECONDS = 1.0


def _node_names(context: RunContext, runner: str) -> list[str]:
    """The node names this host's run will take: its runner, monitor and agent processes."""
    plan = context.plan
    names = [runner] + (["monitor"] if plan.hosts.monitor else [])
    names += ["recorder"] if plan.outputs.record is not None else []
    for agents in partition(plan.hosts.agents, context.agents_per_process):
        names.append(_process_name(agents))
        if len(agents) > 1 and context.plan.packing.agent_nodes != "none":  # ``nodes.hosted``
            names += [f"agent_{a}" for a in agents]
    return names


def _process_name(agents: Sequence[int]) -> str:
    """The node name of the process that hosts ``agents``."""
    return f"agent_{agents[0]}" if len(agents) == 1 else f"agents_{agents[0]}_{agents[-1]}"


def _adopt(env: dict[str, str]) -> None:
    """The runner's own node (the watcher) runs with the environment of its processes."""
    for key in (
        "ROS_AUTOMATIC_DISCOVERY_RANGE",
        "ROS_DOMAIN_ID",
        "RMW_IMPLEMENTATION",
        "FASTRTPS_DEFAULT_PROFILES_FILE",
        "FASTDDS_BUILTIN_TRANSPORTS",
    ) + DISCOVERY_VARIABLES:
        if key in env:
            os.environ[key] = env[key]
        elif key in DISCOVERY_VARIABLES:
            os.environ.pop(key, None)


def _start_server(context: RunContext, directory: str) -> DiscoveryServer | None:
    """``--discovery server`` (no address): a discovery server of this run on 127.0.0.1."""
    envs, spec = context.envs, context.plan.hosts.discovery
    if envs is None or spec.kind != "server" or spec.port:
        return None
    return start_discovery_server(
        envs.spec.port,
        envs.spec.host,
        seconds=context.plan.timing.timeout + 60.0,
        env=envs.for_role("server", context.env),
        log_path=os.path.join(directory, "discovery_server.log"),
    )


def _run_id(plan: RunPlan) -> int:
    """The id given (--run-id), else a fresh random id; on hosts that each run some agents
    (--only), the same id on every host: a hash of what all of them must agree on (scene file,
    times, method, ensemble, domain)."""
    if plan.hosts.run_id is not None:
        return plan.hosts.run_id
    if plan.every_agent_here:
        return random.randrange(1, 2**31 - 1)
    with open(plan.scene_path, "rb") as fh:
        shared = [fh.read()]
    numerics = plan.numerics
    agreed = (plan.scene.t_end, plan.mode, numerics.name, numerics.dt, plan.hosts.ensemble)
    shared += [repr(agreed).encode()]
    shared += [os.environ.get("ROS_DOMAIN_ID", "").encode()]
    digest = hashlib.sha256(b"\0".join(shared)).digest()
    return 1 + int.from_bytes(digest[:4], "big") % (2**31 - 2)


def _configs(context: RunContext) -> tuple[MonitorConfig, AgentConfig]:
    """(the monitor's configuration, every agent process's before its own agents)."""
    plan, timing, k = context.plan, context.plan.timing, context.agents_per_process
    scene, t_end = os.path.abspath(plan.scene_path), plan.scene.t_end
    recorded = int(plan.outputs.record is not None)
    agent = AgentConfig(
        scene=scene, t_end=t_end, mode=plan.mode.value, run_id=context.run_id,
        agents_per_process=k, agent_nodes=context.plan.packing.agent_nodes,
        # the recorder (--record) reads every pose, the monitor every state of the exchange
        pose_subscribers=recorded, exchange_subscribers=int(plan.hosts.monitor),
        autostart=False,  # the runner drives the lifecycle (``lifecycle_driver``)
        integrator=plan.numerics.name, round_timeout=timing.round_timeout,
        # start-up of many processes on few cores takes a while: scale the patience
        discovery_timeout=30.0 + 2.0 * len(partition(plan.n_agents, k)),
        peer_timeout=timing.peer_timeout, peers_restart=plan.on_failure.restart,
        # every agent keeps its latched final pose alive until the lead host has them all: a
        # writer that exits before the runner's reader matched it takes its sample along
        hold_final=REMOTE_FINAL_POSE_SECONDS,
    )
    agent = replace(agent, **_stepping(plan))
    if plan.bridge is not None:
        agent = replace(agent, **bridge_run.agent_fields(plan.bridge, plan.scene.model.order))
    monitor = MonitorConfig(
        scene=scene, t_end=t_end, mode=plan.mode.monitored_as.value,
        peer_timeout=timing.peer_timeout, run_id=context.run_id,
        agents_per_process=k,  # how the agents' states come
        # the recorder (--record) hears every report, the first too (``report_readers``)
        report_readers=recorded,
    )
    return monitor, agent


def _stepping(plan: RunPlan) -> dict[str, Any]:
    """How the agents step: on the wall clock (realtime), or by dt."""
    timing = plan.timing
    if plan.realtime:
        return dict(rate=timing.rate, time_scale=timing.time_scale, start="control",
                    delay=timing.delay)
    return dict(dt=plan.numerics.dt)


def _start(context: RunContext) -> tuple[Child | None, list[Child]]:
    """(monitor or None, agent children): the processes of this host, started.

    ``context.envs`` (DiscoveryEnvironments, None for LOCALHOST) gives the agents the client
    and the monitor (and the recorder) the super-client environment.
    """
    plan = context.plan
    agent_env, monitor_env = context.role_env("client"), context.role_env("super_client")
    monitor_config, agent_config = _configs(context)
    namespace = wire.namespace(plan.hosts.ensemble)
    py = [sys.executable, "-m"]
    monitor = None
    if plan.hosts.monitor:
        argv = py + ["polymatch_ros.ros.nodes.monitor", "--ros-args"]
        argv += ros_args(monitor_config, namespace=namespace, node="monitor")
        monitor = Child("monitor", argv, monitor_env, log_dir=plan.outputs.logs)
    children = []
    for agents in partition(plan.hosts.agents, context.agents_per_process):
        name = _process_name(agents)
        hosted = (dict(agent=agents[0]) if len(agents) == 1 else dict(agents=list(agents)))
        config = replace(agent_config, checkpoint=context.checkpoint_path(name), **hosted)
        remaps = bridge_run.remaps(agents[0]) if plan.bridge is not None else None
        argv = py + ["polymatch_ros.ros.nodes.agent", "--ros-args"]
        argv += ros_args(config, namespace=namespace, node=name, remaps=remaps)
        children.append(Child(name, argv, agent_env, agents, plan.outputs.logs))
    return monitor, children


def _announce(context: RunContext) -> None:
    """The run's first line (stderr, unless --quiet): what runs here, how, where."""
    plan, envs = context.plan, context.envs
    if plan.outputs.quiet:
        return
    n, here = plan.n_agents, len(plan.hosts.agents)
    which = f"{n} agents" if here == n else (
        f"{here} of {n} agents ({describe_agents(plan.hosts.agents)})")
    discovery = context.env["ROS_AUTOMATIC_DISCOVERY_RANGE"] if envs is None else envs.spec
    k = context.agents_per_process
    processes = len(partition(plan.hosts.agents, k))
    packed = (f"{processes} processes" if k == 1 else
              f"{processes} process{'es' if processes > 1 else ''} of up to {k}, agent nodes "
              f"{context.plan.packing.agent_nodes}")
    print(
        f"polymatch run: {which} in {packed} ({context.plan.packing.reason}), "
        f"{plan.mode}, integrator {plan.numerics.name}, dt {plan.numerics.dt:g}, "
        f"ROS_DOMAIN_ID={context.domain}, discovery {discovery}, "
        f"ensemble {wire.namespace(plan.hosts.ensemble)}",
        file=sys.stderr, flush=True,
    )
    print(describe_domain(context.domain, plan.hosts.isolated, str(discovery)), file=sys.stderr,
          flush=True)


def _stop(context: RunContext, children: list[Child], monitor: Child | None,
          watcher: Watcher | None, others: list[Child]) -> None:
    """End every process of the run by its PID (the robots and the recorder last)."""
    stop_all(children, monitor, watcher, recorded=context.plan.outputs.record is not None)
    stop_all(others, None, None)


def _run(context: RunContext, server: DiscoveryServer | None = None) -> int:
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    plan = context.plan
    _announce(context)
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    children: list[Child] = []
    others: list[Child] = []  # bridge mode's robots; the recorder (--record), ended last
    monitor: Child | None = None
    watcher: Watcher | None = None
    supervision: Supervision | None = None
    interrupted: list[int] = []

    def interrupt(sig: int, frame: FrameType | None) -> None:
        interrupted.append(sig)

    old = {s: signal.signal(s, interrupt) for s in (signal.SIGINT, signal.SIGTERM)}
    start = time.monotonic()
    code, message = 1, "not started"
    progress = Progress(plan.scene.t_end, plan.outputs.quiet)
    try:
        name = "runner" if plan.every_agent_here else f"runner_{plan.hosts.agents[0]}"
        watcher = Watcher(plan.scene, plan.hosts.ensemble, name, context.run_id,
                          context.exchange_blocks)
        if context.shared_domain:
            watcher.refuse_names_in_use(_node_names(context, name), GRAPH_LISTEN_SECONDS)
        if plan.hosts.lead and not plan.hosts.monitor:
            watcher.host_ensemble_services(plan.mode)
        if plan.bridge is not None:
            others = bridge_run.robots(plan, context.role_env("client"))  # as the agents
        others += start_recorder(plan, context.env, context.envs, context.directory)
        monitor, children = _start(context)
        supervision = Supervision(plan, watcher, children, monitor, progress, server, others)
        code, message = supervision.watch(interrupted, start)
    except PolymatchError as exc:
        code, message = exc.exit_code, str(exc)
    finally:
        _stop(context, children, monitor, watcher, others)
        for s, h in old.items():
            signal.signal(s, h)
    try:
        wall = time.monotonic() - start
        failures = tuple(supervision.recovery.failures) if supervision is not None else ()
        report(plan, RunOutcome(watcher, children, monitor, progress, code, message, wall,
                                failures, context.checkpoints(children)))
        final = watcher.final_state() if watcher is not None else None
        if code == 0 and plan.hosts.lead and watcher is not None and final is not None:
            code = verdict(plan.scene, final, watcher.stop_requested_at)
        code = report_recording(others, code, plan.outputs.quiet)
    finally:
        sys.stdout.flush()
        sys.stderr.flush()
        with teardown_watchdog(exit_code=code):
            if watcher is not None:
                watcher.destroy()
            if rclpy.ok():
                rclpy.shutdown()
    return code
