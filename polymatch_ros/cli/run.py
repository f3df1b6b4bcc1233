"""`polymatch run SCENE`: its command line, parsed into the options record (``RunOptions``) the
run's plan is built from (``supervisor.plan.build_run_plan``).

Every option is checked there, before any process starts (one line, exit 2): the scene and the
integrator, each option that sets a node's parameter against the parameter's row, --save
writable, --agents-per-process, the ensemble's namespace, --only, the discovery spec, the
ROS_DOMAIN_ID (the user's, which a run across hosts needs set; --isolated: a private one), and
the bridge mode's robots.  The runner (``polymatch_ros.ros.supervisor.runner``) then takes the
plan as it is.  ROS modules are imported when the command runs, not when the parser is built.
"""

from __future__ import annotations

import argparse
from dataclasses import fields

from ..console import add_number_options, positive_float
from ..ros.config.params import AGENT_NODES, CMD_TYPES
from ..ros.supervisor.plan import RunOptions, build_run_plan, node_parameter
from ..ros.supervisor.recovery import POLICIES
from ..ros.wire.modes import MODES


def _default(name: str) -> object:
    """The default of option ``name`` (a ``RunOptions`` field): an option that sets a node's
    parameter has the parameter's (``plan.NODE_OPTIONS``, ``plan.option_default``)."""
    return next(f.default for f in fields(RunOptions) if f.name == name)


# (flag, type, default, help) of the options that set how the agents step and wait
RUN_OPTIONS = (
    ("--rate", positive_float, _default("rate"),
     f"realtime: steps per second (default {_default('rate'):g})"),
    ("--time-scale", positive_float, _default("time_scale"),
     "realtime: simulated seconds per wall-clock second"),
    ("--peer-timeout", positive_float, _default("peer_timeout"),
     "realtime: drop silent peers after S s"),
    ("--delay", float, _default("delay"), "realtime: injected transport delay (s), experiments"),
    ("--round-timeout", positive_float, _default("round_timeout"),
     "lockstep: after S s a round fails if a missing peer has left"),
)

# (flag, type, default, help) of the simulated robots and the agents' command limits
ROBOT_OPTIONS = (
    ("--lag", float, _default("lag"),
     f"robots' actuator time constant (s, default {_default('lag'):g})"),
    ("--position-noise", float, _default("position_noise"),
     f"std of the measured positions (m, default {_default('position_noise'):g})"),
    ("--angle-noise", float, _default("angle_noise"),
     f"std of the measured orientations (rad, default {_default('angle_noise'):g})"),
    ("--max-linear-speed", positive_float, _default("max_linear_speed"),
     "commanded speed limit (m/s)"),
    ("--max-angular-speed", positive_float, _default("max_angular_speed"),
     "commanded angular speed limit (rad/s)"),
    ("--max-linear-accel", positive_float, _default("max_linear_accel"),
     "second order: commanded acceleration limit (m/s^2)"),
    ("--max-angular-accel", positive_float, _default("max_angular_accel"),
     "second order: commanded angular acceleration limit (rad/s^2)"),
)


def cmd_run(args: argparse.Namespace) -> int:
    """Build the plan (every check first), run it, end this process with the run's code."""
    run_plan = build_run_plan(run_options(args))
    from ..ros.process.teardown import end_process
    from ..ros.supervisor.runner import run

    code = run(run_plan)
    end_process(code)  # rclpy ran in this process: no interpreter finalization after it
    return code


def run_options(args: argparse.Namespace) -> RunOptions:
    """The parsed ``polymatch run`` arguments as the options record the plan is built from."""
    return RunOptions(**{f.name: getattr(args, f.name) for f in fields(RunOptions)})


def add_parser(sub: argparse._SubParsersAction) -> None:
    """The ``run`` subcommand."""
    p = sub.add_parser(
        "run", help="run the distributed ROS 2 ensemble of a scene (a node per agent)"
    )
    p.add_argument("scene", help="scene file or shipped scene name")
    p.add_argument("--mode", choices=MODES, default=_default("mode"),
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
        choices=("auto", *AGENT_NODES),
        default=_default("agent_nodes"),
        help="what a process hosting several agents gives each: a node with its pose topics, "
        "services and parameters (full), with its pose topics (lean), none; auto: full "
        "up to 32 agents a process, lean beyond (full nodes slow a large process's start-up)",
    )
    add_number_options(p, RUN_OPTIONS)
    p.add_argument(
        "--hold",
        type=float,
        default=_default("hold"),
        help="stop once the diameter stayed under the tolerance this long (simulated s)",
    )
    _add_ensemble_options(p)
    _add_host_options(p)
    _add_bridge_options(p)
    p.add_argument("--quiet", "-q", action="store_true",
                   help="no first line and no progress; the summary and errors only")
    p.add_argument("--verbose", "-v", action="store_true", help="print every agent's final line")
    p.add_argument("--run-records", metavar="JSONL",
                   help="write every process's run record (JSON, one a line) to this file")
    p.add_argument("--logs", metavar="DIR",
                   help="write each process's whole output (its ROS log lines, its errors) to "
                   "DIR/<node>.log, a restarted process's after its predecessor's")
    p.set_defaults(func=cmd_run)


def _add_bridge_options(p: argparse.ArgumentParser) -> None:
    """The options of the simulated robots (bridge mode)."""
    g = p.add_argument_group("bridge mode (simulated robots)")
    add_number_options(g, ROBOT_OPTIONS)
    g.add_argument("--cmd-vel-type", choices=CMD_TYPES, default=_default("cmd_vel_type"),
                   help="first order: the robots' cmd_vel message, twist_stamped "
                   "(geometry_msgs/TwistStamped, as Jazzy's diff_drive_controller takes; default) "
                   "or twist (geometry_msgs/Twist)")
    g.add_argument("--robot-log", metavar="DIR",
                   help="each robot writes its true and measured pose at every step to "
                   "DIR/robot_<i>.txt")
    g.add_argument("--drive", choices=node_parameter("drive").choices,
                   default=_default("drive"),
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
        help="the run id every message of the run carries (1 .. 2^31 - 1), for agents started "
        "by other programs or hosts (default: chosen, the same on every host of an --only run)",
    )
    p.add_argument(
        "--discovery",
        default=_default("discovery"),
        metavar="SPEC",
        help="DDS discovery: localhost (default), subnet, server[:HOST:PORT] (bare: a server "
        "of this run on 127.0.0.1), peers:ADDR,...",
    )


def _add_ensemble_options(p: argparse.ArgumentParser) -> None:
    """Where and how the ensemble runs: time limit, namespace, hosts, discovery, output."""
    p.add_argument(
        "--timeout",
        type=positive_float,
        default=_default("timeout"),
        help="wall-clock limit for the whole run (s)",
    )
    p.add_argument(
        "--on-failure",
        choices=POLICIES,
        default=_default("on_failure"),
        help="a process that dies: restart it (default; lockstep resumes exactly, realtime "
        "rejoins; 3 deaths within 30 s end the run) or stop the run",
    )
    p.add_argument(
        "--ensemble", default=_default("ensemble"), help="ensemble namespace (default polymatch)"
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
