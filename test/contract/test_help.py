"""The help a newcomer meets: every option says what it does; a node's --help lists its
parameters (name, type, default, range, meaning) from the table it declares them from, and
starts no ROS."""

import argparse
import subprocess
import sys

import pytest

from polymatch_ros.cli import build_parser
from polymatch_ros.ros.config.params import AGENT, MONITOR, ROBOT


def _subparsers(parser):
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return action.choices


def test_every_option_of_every_subcommand_has_a_help_text():
    missing = [f"{name} {a.option_strings[0] if a.option_strings else a.dest}"
               for name, sub in _subparsers(build_parser()).items()
               for a in sub._actions
               if not a.help or a.help == argparse.SUPPRESS or not a.help.strip()]
    assert missing == []


@pytest.mark.parametrize("node, table", [("agent", AGENT), ("monitor", MONITOR),
                                         ("robot", ROBOT)])
@pytest.mark.parametrize("flag", ["--help", "-h"])
def test_node_help_lists_its_parameters_without_starting_ros(node, table, flag):
    code = ("import sys; from polymatch_ros.cli import main; "
            f"code = main([{node!r}, {flag!r}]); "
            "print('ROS imported' if 'rclpy' in sys.modules else 'no ROS'); sys.exit(code)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.rstrip().endswith("no ROS")
    assert out.stderr == ""
    text = out.stdout
    assert f"usage: polymatch {node}" in text
    for p in table:                   # each parameter: its name, its type, its range or choices
        entry = next(line for line in text.splitlines() if line.startswith(f"  {p.name}  ("))
        assert {bool: "bool", int: "int", float: "float", str: "string"}.get(p.kind, "list") \
            in entry
        if p.choices:
            assert ", ".join(p.choices) in entry
        if p.bounds:
            assert "range [" in entry
        assert p.text.split()[0] in text


def test_node_help_after_ros_args_is_the_nodes_business():
    """``--ros-args ... --help``: ``-h``/``--help`` there belongs to ROS, not to the help table."""
    from polymatch_ros.cli.node_help import wants_help
    assert wants_help(["--help"]) and wants_help(["-h", "--ros-args", "-p", "x:=1"])
    assert not wants_help(["--ros-args", "--help"])
