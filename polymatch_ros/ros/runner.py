"""`polymatch run SCENE`: a whole distributed ensemble from one scene file, without launch.

Starts the monitor and one process per agent (or per K agents) in the ensemble's namespace
(``-r __ns:=/<ensemble>``, nodes ``agent_<i>`` and ``monitor``), all with loopback discovery
and a fresh ROS_DOMAIN_ID unless the user set them; shows progress (simulated time,
diameter, rounds/s); stops at t_end or once the diameter has stayed under the scene's
tolerance; prints a summary (final diameters per group, in lockstep the deviation from the
centralised solution, wall time, rounds/s) from the agents' final poses and run records; and
ends every process it started, by PID, also on Ctrl-C and when a child dies.
"""

import hashlib
import os
import random
import signal
import sys
import tempfile
import time

from ..console import Progress, add_number_options, positive_float, writable_output
from ..core.errors import ParameterError, PolymatchError
from ..core.scene import load_scene, resolve_scene_path
from ..core.simulate import plan
from . import bridge_run, wire
from .children import (  # noqa: F401 (API)
    LOCALHOST_PARTICIPANTS,
    REMOTE_FINAL_POSE_SECONDS,
    Child,
    Supervision,
    _agents_per_process,
    describe_agents,
    fewest_agents_per_process,
    parse_only,
    partition,
    stop_all,
)
from .discovery import (
    DISCOVERY_VARIABLES,
    discovery_environments,
    parse_discovery_spec,
    start_discovery_server,
)
from .ros_env import end_process, reserved_domain_id, ros_environment, teardown_watchdog
from .summary import report, verdict
from .watcher import Watcher


def _check_ensemble(name):
    from rclpy.exceptions import InvalidNamespaceException
    from rclpy.validate_namespace import validate_namespace

    try:
        validate_namespace(wire.namespace(name))
    except InvalidNamespaceException:
        raise PolymatchError(
            f"--ensemble: {name!r} is not a valid ROS namespace "
            f"(letters, digits, underscores; not starting with a digit)"
        ) from None


def cmd_run(args):
    scene_path = resolve_scene_path(args.scene)
    scene = load_scene(scene_path, {"time.t_end": args.t_end})
    rt = args.mode != "lockstep"
    if args.mode == "bridge":
        scene = bridge_run.prepare(args, scene)  # the noise-floor tolerance
        args.time_scale = 1.0  # robots move in real time
    dt = args.time_scale / args.rate if rt else args.dt
    the_plan = plan(scene, args.integrator, dt, distributed=True)  # one-line errors first
    if args.save:
        args.save = writable_output(args.save, ".npz")     # checked before a long run
    if args.agents_per_process is not None and args.agents_per_process < 1:
        raise PolymatchError("--agents-per-process must be >= 1")
    _check_ensemble(args.ensemble)
    n = scene.model.n_agents
    args.agents = list(range(n)) if args.only is None else parse_only(args.only, n)
    args.lead = args.monitor or len(args.agents) == n
    spec = parse_discovery_spec(args.discovery)
    if len(args.agents) < n and not os.environ.get("ROS_DOMAIN_ID"):
        raise ParameterError(
            "--only: set the same ROS_DOMAIN_ID on every host (e.g. export ROS_DOMAIN_ID=17)"
        )
    with reserved_domain_id() as domain, tempfile.TemporaryDirectory(
        prefix="polymatch_run_"
    ) as directory:
        env = ros_environment(domain)
        envs = None if spec.kind == "localhost" else discovery_environments(spec, directory)
        args.agents_per_process = _agents_per_process(
            args, len(args.agents), envs is None and _localhost(env)
        )
        _adopt(env if envs is None else envs.for_role("super_client", env))
        server = _start_server(spec, envs, env, args, directory)
        try:
            code = _run(args, scene, scene_path, the_plan, env, domain, envs)
        finally:
            if server is not None:
                server.stop()
    end_process(code)  # rclpy ran in this process: no interpreter finalization after it


def _localhost(env):
    return env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"


def _adopt(env):
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


def _start_server(spec, envs, env, args, directory):
    """``--discovery server`` (no address): a discovery server of this run on 127.0.0.1."""
    if envs is None or spec.kind != "server" or spec.port:
        return None
    return start_discovery_server(
        envs.spec.port,
        envs.spec.host,
        seconds=args.timeout + 60.0,
        env=envs.for_role("server", env),
        log_path=os.path.join(directory, "discovery_server.log"),
    )


def _run_id(args, scene, scene_path, the_plan):
    """A fresh random id; on hosts that each run some agents (--only), the same id on every
    host: a hash of what all of them must agree on (scene file, times, method, ensemble,
    domain)."""
    if len(args.agents) == scene.model.n_agents:
        return random.randrange(1, 2**31 - 1)
    with open(scene_path, "rb") as fh:
        shared = [fh.read()]
    shared += [repr((scene.t_end, args.mode, the_plan.name, the_plan.dt, args.ensemble)).encode()]
    shared += [os.environ.get("ROS_DOMAIN_ID", "").encode()]
    digest = hashlib.sha256(b"\0".join(shared)).digest()
    return 1 + int.from_bytes(digest[:4], "big") % (2**31 - 2)


def _node_args(args, scene, scene_path, the_plan):
    """(--ros-args of the monitor, of every agent process) without the node's own remaps."""
    n = scene.model.n_agents
    common = [
        "-r",
        f"__ns:={wire.namespace(args.ensemble)}",
        "-p",
        f"scene:={os.path.abspath(scene_path)}",
        "-p",
        f"t_end:={scene.t_end!r}",
    ]
    agent = common + [
        "-p",
        f"mode:={args.mode}",
        "-p",
        f"run_id:={_run_id(args, scene, scene_path, the_plan)}",
        "-p",
        f"agents_per_process:={args.agents_per_process}",
        "-p",
        f"pose_subscribers:={1 if args.monitor else 0}",
        "-p",
        "autostart:=false",  # the runner drives the lifecycle (``lifecycle_driver``)
        "-p",
        f"integrator:={the_plan.name}",
        "-p",
        f"round_timeout:={args.round_timeout!r}",
        # start-up of many processes on few cores takes a while: scale the patience
        "-p",
        f"discovery_timeout:={30.0 + 2.0 * len(partition(n, args.agents_per_process))!r}",
        "-p",
        f"peer_timeout:={args.peer_timeout!r}",
        "-p",
        # every agent keeps its latched final pose alive until the lead host has them all: a
        # writer that exits before the runner's reader matched it takes its sample along
        f"hold_final:={REMOTE_FINAL_POSE_SECONDS!r}",
    ]
    if args.mode != "lockstep":
        agent += [
            "-p",
            f"rate:={args.rate!r}",
            "-p",
            f"time_scale:={args.time_scale!r}",
            "-p",
            "start_time:=-1.0",
            "-p",
            f"delay:={args.delay!r}",
        ]
    else:
        agent += ["-p", f"dt:={the_plan.dt!r}"]
    if args.mode == "bridge":
        agent += bridge_run.agent_args(args)
    monitor_mode = "lockstep" if args.mode == "lockstep" else "realtime"
    monitor = common + ["-p", f"mode:={monitor_mode}"]
    monitor += ["-p", f"peer_timeout:={args.peer_timeout!r}"]
    if args.mode != "lockstep":
        monitor += ["-p", "rate:=10.0"]
    return monitor, agent


def _start(args, scene, scene_path, the_plan, env, envs=None):
    """(monitor or None, agent children): the processes of this host, started.

    ``envs`` (DiscoveryEnvironments, None for LOCALHOST) gives the agents the client and the
    monitor the super-client environment.
    """
    agent_env = env if envs is None else envs.for_role("client", env)
    monitor_env = env if envs is None else envs.for_role("super_client", env)
    mon_args, agent_args = _node_args(args, scene, scene_path, the_plan)
    py = [sys.executable, "-m"]
    monitor = None
    if args.monitor:
        monitor = Child(
            "monitor",
            py
            + ["polymatch_ros.ros.monitor_node", "--ros-args"]
            + mon_args
            + ["-r", "__node:=monitor"],
            monitor_env,
        )
    children = []
    for agents in partition(args.agents, args.agents_per_process):
        name = f"agent_{agents[0]}" if len(agents) == 1 else f"agents_{agents[0]}_{agents[-1]}"
        sel = (
            ["-p", f"agent:={agents[0]}"]
            if len(agents) == 1
            else ["-p", "agents:=[" + ",".join(map(str, agents)) + "]"]
        )
        children.append(
            Child(
                name,
                py
                + ["polymatch_ros.ros.agent_node", "--ros-args"]
                + agent_args
                + sel
                + (bridge_run.remaps(agents[0]) if args.mode == "bridge" else [])
                + ["-r", f"__node:={name}"],
                agent_env,
            )
        )
    return monitor, children


def _announce(args, n, the_plan, env, domain, envs):
    """The run's first line (stderr, unless --quiet): what runs here, how, where."""
    if args.quiet:
        return
    here = len(args.agents)
    which = f"{n} agents" if here == n else (
        f"{here} of {n} agents ({describe_agents(args.agents)})")
    print(
        f"polymatch run: {which} in {len(partition(here, args.agents_per_process))} processes, "
        f"{args.mode}, integrator {the_plan.name}, dt {the_plan.dt:g}, ROS_DOMAIN_ID={domain}, "
        f"discovery {env['ROS_AUTOMATIC_DISCOVERY_RANGE'] if envs is None else envs.spec}, "
        f"ensemble {wire.namespace(args.ensemble)}",
        file=sys.stderr, flush=True,
    )


def _run(args, scene, scene_path, the_plan, env, domain, envs=None):
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    n, here = scene.model.n_agents, len(args.agents)
    _announce(args, n, the_plan, env, domain, envs)
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    children, monitor, watcher, robots = [], None, None, []
    interrupted = []
    old = {
        s: signal.signal(s, lambda sig, frame: interrupted.append(sig))
        for s in (signal.SIGINT, signal.SIGTERM)
    }
    start = time.monotonic()
    code, message = 1, "not started"
    progress = Progress(scene.t_end, args.quiet)
    try:
        name = "runner" if here == n else f"runner_{args.agents[0]}"
        watcher = Watcher(scene, args.ensemble, name)
        if args.lead and not args.monitor:
            watcher.host_ensemble_services(args.mode)
        if args.mode == "bridge":
            robots = bridge_run.robots(args, scene_path, env)
        monitor, children = _start(args, scene, scene_path, the_plan, env, envs)
        run = Supervision(args, scene, the_plan, watcher, children, monitor, progress)
        code, message = run.watch(interrupted, start)
    except PolymatchError as exc:
        code, message = exc.exit_code, str(exc)
    finally:
        stop_all(children, monitor, watcher)
        stop_all(robots, None, None)
        for s, h in old.items():
            signal.signal(s, h)
    try:
        wall = time.monotonic() - start
        report(args, scene, the_plan, watcher, children, monitor, progress, code, message, wall)
        summarised = args.lead and watcher.final_state() is not None
        code = verdict(scene, watcher) if code == 0 and summarised else code
    finally:
        sys.stdout.flush()
        sys.stderr.flush()
        with teardown_watchdog(exit_code=code):
            if watcher is not None:
                watcher.destroy()
            if rclpy.ok():
                rclpy.shutdown()
    return code


# (flag, type, default, help) of the options that set how the agents step and wait
RUN_OPTIONS = (
    ("--rate", positive_float, 50.0, "realtime: steps per second (default 50)"),
    ("--time-scale", positive_float, 1.0, "realtime: simulated seconds per wall-clock second"),
    ("--peer-timeout", positive_float, 1.0, "realtime: drop silent peers after S s"),
    ("--delay", float, 0.0, "realtime: injected transport delay (s), experiments"),
    ("--round-timeout", positive_float, 10.0,
     "lockstep: after S s a round fails if a missing peer has left"),
)


def add_parser(sub):
    p = sub.add_parser(
        "run", help="run the distributed ROS 2 ensemble of a scene (one process per agent)"
    )
    p.add_argument("scene", help="scene file or shipped scene name")
    p.add_argument("--mode", choices=("lockstep", "realtime", "bridge"), default="lockstep",
                   help="bridge: simulated robots driven by bridged agents")
    p.add_argument("--integrator", "-i", metavar="NAME",
                   help="fixed-step integrator (default: the scene's)")
    p.add_argument("--dt", type=positive_float, help="lockstep step size (default: the scene's)")
    p.add_argument("--t-end", type=positive_float, help="override time.t_end")
    p.add_argument(
        "--agents-per-process",
        "-k",
        type=int,
        default=None,
        metavar="K",
        help="agents per process (default 1, or the fewest that keep the processes within the 32 "
        "DDS participants that LOCALHOST discovery reaches)",
    )
    add_number_options(p, RUN_OPTIONS)
    p.add_argument(
        "--hold",
        type=float,
        default=1.0,
        help="stop once the diameter stayed under the tolerance this long (simulated s)",
    )
    _add_ensemble_options(p)
    bridge_run.add_arguments(p)
    p.add_argument("--quiet", "-q", action="store_true")
    p.add_argument("--verbose", "-v", action="store_true", help="print every agent's final line")
    p.add_argument("--records", metavar="JSONL",
                   help="write every process's run record (JSON, one a line) to this file")
    p.set_defaults(func=cmd_run)


def _add_ensemble_options(p):
    """Where and how the ensemble runs: time limit, namespace, hosts, discovery, output."""
    p.add_argument(
        "--timeout",
        type=positive_float,
        default=600.0,
        help="wall-clock limit for the whole run (s)",
    )
    p.add_argument(
        "--ensemble", default="polymatch", help="ensemble namespace (default polymatch)"
    )
    p.add_argument(
        "--no-monitor",
        dest="monitor",
        action="store_false",
        help="do not start the monitor (on every host but one of a run across hosts)",
    )
    p.add_argument(
        "--only",
        metavar="RANGE",
        help="run only these agents on this host, e.g. 0-7,12 (the others run on other hosts "
        "with the same ROS_DOMAIN_ID, --ensemble and --discovery)",
    )
    p.add_argument(
        "--discovery",
        default="localhost",
        metavar="SPEC",
        help="DDS discovery: localhost (default), subnet, server[:HOST:PORT] (bare: a server "
        "of this run on 127.0.0.1), peers:ADDR,...",
    )
    p.add_argument(
        "--no-compare",
        dest="compare",
        action="store_false",
        help="lockstep: skip the comparison with the centralised simulation",
    )
    p.add_argument(
        "--save", metavar="NPZ", help="save the final poses received from the agents (npz)"
    )
