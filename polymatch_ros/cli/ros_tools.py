"""The small ROS tools: ``polymatch echo TOPIC`` and ``polymatch set NAME VALUE``.

    polymatch echo /polymatch/diameter --until-below 1e-6   print a topic (``ros.nodes.echo``)
    polymatch set kappa 2.0 --ensemble team_b               a runtime parameter on every agent
                                                            (``ros.supervisor.param_set``)

Their arguments are checked here; rclpy is imported when the command runs.
"""

from __future__ import annotations

import argparse
import os

from ..core.errors import ParameterError
from ..ros.config.params import RUNTIME


def cmd_echo(args: argparse.Namespace) -> int:
    """Print the messages of ``args.topic`` (``ros.nodes.echo.echo``); its exit code."""
    if not args.topic.startswith("/"):
        raise ParameterError(f"topic must be absolute (start with /), got {args.topic!r}")
    if args.timeout is not None and not args.timeout > 0:
        raise ParameterError(f"--timeout must be > 0 s, got {args.timeout:g}")
    from ..ros.network.environment import ros_environment
    from ..ros.nodes.echo import echo

    os.environ.update(ros_environment())  # the discovery of `polymatch run` unless set otherwise
    return echo(args.topic, args.count, args.until_below, args.timeout, as_json=args.json)


def cmd_set(args: argparse.Namespace) -> int:
    """Set ``args.name`` on every agent of ``args.ensemble``; ends the process with the code."""
    from ..ros.process.teardown import end_process
    from ..ros.supervisor.param_set import set_parameter

    code = set_parameter(args.name, args.value, args.ensemble, args.timeout)
    end_process(code)  # rclpy ran in this process: no interpreter finalization after it
    return code


def add_parser(sub: argparse._SubParsersAction) -> None:
    """The ``echo`` and ``set`` subcommands."""
    p = sub.add_parser("echo", help="print messages of a topic (stand-in for `ros2 topic echo`)")
    p.add_argument("topic", help="absolute topic name, e.g. /polymatch/diameter")
    p.add_argument("--count", type=int, help="exit after this many messages")
    p.add_argument(
        "--until-below", type=float, metavar="X", help="exit 0 once a Float64 value is below X"
    )
    p.add_argument("--timeout", type=float, metavar="S",
                   help="give up after S seconds (exit 1); default: give up when no message came "
                   "within 10 s, saying which ROS domain and discovery range it listened in")
    p.add_argument("--json", action="store_true",
                   help="one JSON object a message and line (fields by name), for programs")
    p.set_defaults(func=cmd_echo)

    p = sub.add_parser("set", help="set a runtime parameter (kappa, gamma, mass, rate, limits) on "
                                   "every agent of a running ensemble")
    p.add_argument("name", help=f"one of {', '.join(RUNTIME)}")
    p.add_argument("value", help="the new value (checked against the parameter's range)")
    p.add_argument("--ensemble", default="polymatch", help="ensemble namespace")
    p.add_argument("--timeout", type=float, default=10.0,
                   help="seconds to find the agents and hear their answers (default 10)")
    p.set_defaults(func=cmd_set)
