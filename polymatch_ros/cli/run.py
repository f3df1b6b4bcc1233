"""`polymatch run SCENE`: its command line, and the ``RunPlan`` built and checked from it once.

Every option is checked here, before any process starts (one line, exit 2): the scene and the
integrator, --save writable, --agents-per-process, the ensemble's namespace, --only, the
discovery spec, the ROS_DOMAIN_ID (the user's, which a run across hosts needs set; --isolated:
a private one), and the bridge mode's robots.  The runner (``polymatch_ros.ros.supervisor.runner``)
then takes the plan as it is.  ROS modules are imported when the command runs, not when the
parser is built.
"""

from __future__ import annotations

import argparse
import os

from ..console import add_number_options, positive_float, writable_output
from ..core.errors import ParameterError, PolymatchError
from ..core.scenes.scene import Scene, resolve_scene_path
from ..core.stepping.simulate import choose_numerics
from ..ros.config.params import CMD_TYPES
from ..ros.supervisor.plan import BridgeOptions, Hosts, Outputs, RunPlan, Timing
from ..ros.supervisor.recovery import POLICIES, RestartPolicy
from ..ros.wire.modes import MODES, Mode
from .scene_commands import check_integrator_option, load_scene_options, naming_dt_option

# (flag, type, default, help) of the options that set how the agents step and wait
RUN_OPTIONS = (
    ("--rate", positive_float, 50.0, "realtime: steps per second (default 50)"),
    ("--time-scale", positive_float, 1.0, "realtime: simulated seconds per wall-clock second"),
    ("--peer-timeout", positive_float, 1.0, "realtime: drop silent peers after S s"),
    ("--delay", float, 0.0, "realtime: injected transport delay (s), experiments"),
    ("--round-timeout", positive_float, 10.0,
     "lockstep: after S s a round fails if a missing peer has left"),
)

# (flag, type, default, help) of the simulated robots and the agents' command limits
ROBOT_OPTIONS = (
    ("--lag", float, 0.1, "robots' actuator time constant (s, default 0.1)"),
    ("--position-noise", float, 0.001, "std of the measured positions (m, default 0.001)"),
    ("--angle-noise", float, 0.001, "std of the measured orientations (rad, default 0.001)"),
    ("--max-linear-speed", positive_float, 1e6, "commanded speed limit (m/s)"),
    ("--max-angular-speed", positive_float, 1e6, "commanded angular speed limit (rad/s)"),
    ("--max-linear-accel", positive_float, 1e6,
     "second order: commanded acceleration limit (m/s^2)"),
    ("--max-angular-accel", positive_float, 1e6,
     "second order: commanded angular acceleration limit (rad/s^2)"),
)


def cmd_run(args: argparse.Namespace) -> int:
    """Build the plan (every check first), run it, end this process with the run's code."""
    run_plan = build_plan(args)
    from ..ros.process.teardown import end_process
    from ..ros.supervisor.runner import run

    code = run(run_plan)
    end_process(code)  # rclpy ran in this process: no interpreter finalization after it
    return code


def build_plan(args: argparse.Namespace) -> RunPlan:
    """The checked ``RunPlan`` of the parsed ``polymatch run`` arguments; one-line errors."""
    check_integrator_option(args.integrator)
    scene_path = resolve_scene_path(args.scene)
    scene = load_scene_options(scene_path, args.t_end)
    bridge, mode = None, Mode(args.mode)
    if mode.drives_robots:
        from ..ros.supervisor import bridge_run

        bridge = _bridge_options(args)
        scene = bridge_run.prepare(scene, bridge, args.only)  # the noise-floor tolerance
    timing = _timing(args, bridge is not None)
    dt = mode.tick_step(timing.rate, timing.time_scale) if mode.ticks else args.dt
    with naming_dt_option(args.dt if mode.exact else None):  # errors first
        numerics = choose_numerics(scene, args.integrator, dt, distributed=True)
    outputs = Outputs(
        save=writable_output(args.save, ".npz") if args.save else None,  # before a long run
        records=args.records,
        quiet=args.quiet,
        verbose=args.verbose,
        compare=args.compare,
        record=writable_output(args.record, ".mcap") if args.record else None,
        logs=_log_directory(args.logs) if args.logs else None,
    )
    hosts = _hosts(args, scene, bridge is not None)
    on_failure = RestartPolicy(restart=args.on_failure == "restart")
    return RunPlan(scene_path, scene, numerics, mode, hosts, timing, outputs, bridge,
                   on_failure)


def _log_directory(path: str) -> str:
    """``--logs DIR``, made if it is not there; one line if it cannot be written."""
    try:
        os.makedirs(path, exist_ok=True)
    except OSError as exc:
        raise ParameterError(f"--logs: cannot make {path!r}: {exc.strerror}") from None
    if not os.access(path, os.W_OK | os.X_OK):
        raise ParameterError(f"--logs: {path!r} is not writable")
    return os.path.abspath(path)


def _timing(args: argparse.Namespace, bridge: bool) -> Timing:
    return Timing(
        timeout=args.timeout,
        hold=args.hold,
        rate=args.rate,
        time_scale=1.0 if bridge else args.time_scale,  # robots move in real time
        peer_timeout=args.peer_timeout,
        delay=args.delay,
        round_timeout=args.round_timeout,
    )


def _bridge_options(args: argparse.Namespace) -> BridgeOptions:
    return BridgeOptions(
        lag=args.lag,
        position_noise=args.position_noise,
        angle_noise=args.angle_noise,
        max_linear_speed=args.max_linear_speed,
        max_angular_speed=args.max_angular_speed,
        max_linear_accel=args.max_linear_accel,
        max_angular_accel=args.max_angular_accel,
        robot_log=args.robot_log,
        drive=args.drive,
        cmd_vel_type=args.cmd_vel_type,
    )


def _hosts(args: argparse.Namespace, scene: Scene, bridge: bool) -> Hosts:
    """This host's share of the ensemble: -k, the namespace, --only, discovery."""
    from ..ros.network.discovery import parse_discovery_spec
    from ..ros.supervisor.children import parse_only

    requested = 1 if bridge else args.agents_per_process  # bridge: one robot, one agent
    if requested is not None and requested < 1:
        raise PolymatchError("--agents-per-process must be >= 1")
    check_ensemble(args.ensemble)
    n = scene.model.n_agents
    agents = tuple(range(n)) if args.only is None else tuple(parse_only(args.only, n))
    spec = parse_discovery_spec(args.discovery)
    if len(agents) < n and not os.environ.get("ROS_DOMAIN_ID"):
        raise ParameterError(
            "--only: set the same ROS_DOMAIN_ID on every host (e.g. export ROS_DOMAIN_ID=17)"
        )
    if len(agents) < n and args.isolated:
        raise ParameterError("--isolated: a run across hosts (--only) needs the same "
                             "ROS_DOMAIN_ID on every host, not a private one")
    if not args.isolated:
        from ..ros.network.environment import user_domain_id

        try:
            user_domain_id()
        except ValueError as exc:
            raise ParameterError(str(exc)) from None
    lead = args.monitor or len(agents) == n
    if args.run_id is not None and not 1 <= args.run_id < 2**63:
        raise ParameterError(f"--run-id: {args.run_id} is not in 1 .. 2^63 - 1")
    return Hosts(args.ensemble, agents, args.monitor, lead, spec, requested, args.agent_nodes,
                 args.isolated, args.run_id)


def check_ensemble(name: str) -> None:
    """PolymatchError (one line) unless ``/<name>`` is a valid ROS namespace."""
    from rclpy.exceptions import InvalidNamespaceException
    from rclpy.validate_namespace import validate_namespace

    from ..ros import wire

    try:
        validate_namespace(wire.namespace(name))
    except InvalidNamespaceException:
        raise PolymatchError(
            f"--ensemble: {name!r} is not a valid ROS namespace "
            f"(letters, digits, underscores; not starting with a digit)"
        ) from None


def add_parser(sub: argparse._SubParsersAction) -> None:
    """The ``run`` subcommand."""
    p = sub.add_parser(
        "run", help="run the distributed ROS 2 ensemble of a scene (a node per agent)"
    )
    p.add_argument("scene", help="scene file or shipped scene name")
    p.add_argument("--mode", choices=MODES, default=Mode.LOCKSTEP.value,
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
        help="agents per process (default: lockstep and realtime up to 4096 a process, the "
        "measured packing; bridge, and realtime on a host of some agents (--only), 1, or the "
        "fewest that keep the processes within the 32 DDS participants that LOCALHOST discovery "
        "reaches); the first line says which and why",
    )
    p.add_argument(
        "--agent-nodes",
        choices=("auto", "full", "lean", "none"),
        default="auto",
        help="what a process hosting several agents gives each: a node with its pose topics, "
        "services and parameters (full), with its pose topics (lean), none; auto: full "
        "up to 32 agents a process, lean beyond (full nodes slow a large process's start-up)",
    )
    add_number_options(p, RUN_OPTIONS)
    p.add_argument(
        "--hold",
        type=float,
        default=1.0,
        help="stop once the diameter stayed under the tolerance this long (simulated s)",
    )
    _add_ensemble_options(p)
    _add_host_options(p)
    _add_bridge_options(p)
    p.add_argument("--quiet", "-q", action="store_true",
                   help="no first line and no progress; the summary and errors only")
    p.add_argument("--verbose", "-v", action="store_true", help="print every agent's final line")
    p.add_argument("--records", metavar="JSONL",
                   help="write every process's run record (JSON, one a line) to this file")
    p.add_argument("--logs", metavar="DIR",
                   help="write each process's whole output (its ROS log lines, its errors) to "
                   "DIR/<node>.log, a restarted process's after its predecessor's")
    p.set_defaults(func=cmd_run)


def _add_bridge_options(p: argparse.ArgumentParser) -> None:
    """The options of the simulated robots (bridge mode)."""
    g = p.add_argument_group("bridge mode (simulated robots)")
    add_number_options(g, ROBOT_OPTIONS)
    g.add_argument("--cmd-vel-type", choices=CMD_TYPES, default=CMD_TYPES[0],
                   help="first order: the robots' cmd_vel message, twist_stamped "
                   "(geometry_msgs/TwistStamped, as Jazzy's diff_drive_controller takes; default) "
                   "or twist (geometry_msgs/Twist)")
    g.add_argument("--robot-log", metavar="DIR",
                   help="each robot writes its true and measured pose at every step to "
                   "DIR/robot_<i>.txt")
    g.add_argument("--drive", choices=("holonomic", "unicycle"), default="holonomic",
                   help="the simulated robots' base: unicycle = differential drive, driven by "
                   "the point ahead of its axle (first order, 2-D)")


def _add_host_options(p: argparse.ArgumentParser) -> None:
    """Which agents run on this host, the run's id, and how DDS discovers the others."""
    p.add_argument(
        "--only",
        metavar="RANGE",
        help="run only these agents on this host, e.g. 0-7,12 (the others run on other hosts "
        "with the same ROS_DOMAIN_ID, --ensemble and --discovery)",
    )
    p.add_argument(
        "--run-id",
        type=int,
        metavar="ID",
        help="the run id every message of the run carries (1 .. 2^63 - 1), for agents started "
        "by other programs or hosts (default: chosen, the same on every host of an --only run)",
    )
    p.add_argument(
        "--discovery",
        default="localhost",
        metavar="SPEC",
        help="DDS discovery: localhost (default), subnet, server[:HOST:PORT] (bare: a server "
        "of this run on 127.0.0.1), peers:ADDR,...",
    )


def _add_ensemble_options(p: argparse.ArgumentParser) -> None:
    """Where and how the ensemble runs: time limit, namespace, hosts, discovery, output."""
    p.add_argument(
        "--timeout",
        type=positive_float,
        default=600.0,
        help="wall-clock limit for the whole run (s)",
    )
    p.add_argument(
        "--on-failure",
        choices=POLICIES,
        default="restart",
        help="a process that dies: restart it (default; lockstep resumes exactly, realtime "
        "rejoins; 3 deaths within 30 s end the run) or stop the run",
    )
    p.add_argument(
        "--ensemble", default="polymatch", help="ensemble namespace (default polymatch)"
    )
    p.add_argument(
        "--isolated",
        action="store_true",
        help="run in a fresh ROS domain of its own, which nothing else hears (tests, "
        "benchmarks); default: your ROS graph (your ROS_DOMAIN_ID, or ROS's default 0), which a "
        "second shell sees",
    )
    p.add_argument(
        "--no-monitor",
        dest="monitor",
        action="store_false",
        help="do not start the monitor (on every host but one of a run across hosts)",
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
    p.add_argument("--record", metavar="MCAP",
                   help="record the run's topics (poses, twists, diameters, diagnostics, markers, "
                   "status) to an MCAP file (`polymatch plot` draws it; `ros2 bag` reads it)")
