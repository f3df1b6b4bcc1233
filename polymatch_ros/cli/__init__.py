"""`polymatch` — one command, subcommands for every job.

    polymatch simulate SCENE     centralised run: progress, summary table, npz, PNG snapshots
    polymatch explain SCENE      which model, representation and integrator, and why
    polymatch integrators        the registry: order, evaluations and exchange rounds per step
    polymatch scenes             the scenes shipped in config/
    polymatch run SCENE          the distributed ROS 2 ensemble (one process per agent) + monitor
    polymatch agent | monitor    single ROS 2 nodes (= `ros2 run polymatch_ros agent|monitor`)
    polymatch robot              a simulated robot for bridge mode (= `ros2 run ... robot`)
    polymatch echo TOPIC         print a topic (stand-in for `ros2 topic echo`)
    polymatch set NAME VALUE     set a parameter on every agent of a running ensemble
    polymatch sweep [SCENE]      many random ensembles in batches: which initial states match
    polymatch record TOPIC... -o FILE   record topics of a running ensemble (MCAP)
    polymatch plot FILE          diameters against time and snapshots from a recording

Errors are one line on stderr and a non-zero exit code: 2 for bad input
(scene, parameters, command line), 3 for a run that did not converge although
the scene expects it, 4 for a `polymatch run` ended by the ensemble's stop service
before it converged, 1 for anything else.  POLYMATCH_DEBUG=1 shows the
traceback of an unexpected error instead of its one line.

The benchmarks live beside the package, in a checkout: ``python -m benchmarks FAMILY``.
"""

from __future__ import annotations

import argparse
import functools
import importlib
import os
import sys
import warnings
from collections.abc import Callable, Sequence
from typing import Any, NoReturn

from ..core.errors import PolymatchError
from .node_help import node_help, wants_help

#: the modules whose ``add_parser(sub)`` adds subcommands, in ``--help`` order; a module that
#: fails to import is an error, never a subcommand silently missing
COMMAND_MODULES: tuple[str, ...] = (
    "polymatch_ros.cli.scene_commands",      # simulate, explain, integrators, scenes
    "polymatch_ros.cli.run",                 # run
    "polymatch_ros.cli.ros_tools",           # echo, set
    "polymatch_ros.cli.sweep",               # sweep
    "polymatch_ros.cli.trade",               # trade
    "polymatch_ros.cli.record",              # record, plot
)

#: single ROS nodes: ``polymatch NAME ARGS`` = ``ros2 run polymatch_ros NAME ARGS``
NODES: dict[str, str] = {"agent": "polymatch_ros.ros.nodes.agent",
                         "monitor": "polymatch_ros.ros.nodes.monitor",
                         "robot": "polymatch_ros.ros.nodes.robot"}


class Parser(argparse.ArgumentParser):
    """argparse with one-line errors (``polymatch: error: ...; see ...--help``), exit code 2.

    Subparsers inherit the class (``add_subparsers`` uses the parent's), so every
    subcommand, including those other modules add, reports parse errors the same way.
    """

    def error(self, message: str) -> NoReturn:
        hint = f"see `{self.prog} --help`"
        self.exit(2, f"polymatch: error: {message.splitlines()[0]} ({hint})\n")


@functools.cache
def build_parser() -> Parser:
    """The ``polymatch`` parser with every subcommand of ``COMMAND_MODULES`` and ``NODES``.

    Built once per process (each ``parse_args`` makes its own namespace), for callers that run
    ``main`` many times in one process."""
    parser = Parser(prog="polymatch", description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for module in COMMAND_MODULES:
        importlib.import_module(module).add_parser(sub)
    for name in NODES:
        sub.add_parser(name, help=f"one {name} node (ROS 2); takes the same arguments as "
                                  f"`ros2 run polymatch_ros {name}`, "
                                  f"e.g. --ros-args -p scene:=FILE; "
                                  f"`polymatch {name} --help` lists its parameters")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """The ``polymatch`` command: its exit code (errors as one line on stderr)."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv and argv[0] in NODES:
        if wants_help(argv[1:]):
            print(node_help(argv[0]))
            return 0
        main_of = importlib.import_module(NODES[argv[0]]).main
        return main_of([f"polymatch {argv[0]}"] + argv[1:])
    parser = build_parser()
    args = parser.parse_args(argv)
    warnings.showwarning = _one_line_warning
    return run_reporting_errors("polymatch", lambda: args.func(args))


def run_reporting_errors(prog: str, command: Callable[[], int]) -> int:
    """``command()``'s exit code, any error reported as one line ``PROG: error: ...`` (the
    contract: never a traceback unless POLYMATCH_DEBUG=1): 2 for bad input, 130 when
    interrupted, 1 otherwise."""
    try:
        return command()
    except PolymatchError as exc:
        print(f"{prog}: error: {_one_line(exc)}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr)
        return 130
    except MemoryError:
        print(f"{prog}: error: out of memory; lower the scene's sizes or --memory-limit",
              file=sys.stderr)
        return 1
    except Exception as exc:  # noqa: BLE001 -- the contract: one line, never a traceback
        if os.environ.get("POLYMATCH_DEBUG"):
            raise
        print(f"{prog}: internal error: {type(exc).__name__}: {_one_line(exc)} "
              f"(POLYMATCH_DEBUG=1 shows the traceback)", file=sys.stderr)
        return 1


def _one_line(exc: object) -> str:
    text = " ".join(str(exc).split())
    return text if len(text) <= 400 else text[:397] + "..."


def _one_line_warning(message: Warning | str, *args: Any, **kwargs: Any) -> None:
    print(f"polymatch: warning: {_one_line(message)}", file=sys.stderr)

