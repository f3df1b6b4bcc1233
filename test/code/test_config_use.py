"""Parameters travel typed: the package writes a node's ``name:=value`` arguments in one place
(``ros.config.configs.ros_args``), and outside the parameter room (``ros/config``) no code reads
a parameter by its name as a string key (``params["rate"]``): the nodes read their typed
configuration (``config.rate``).  Both are checked on the syntax tree of every module (the
string keys in the ROS layer and the commands: the core takes plain values), and the checkers
on sources written here."""

import ast
import pathlib
import re

import pytest

from polymatch_ros.ros.config.params import AGENT, MONITOR, RECORDER, ROBOT

ROOT = pathlib.Path(__file__).resolve().parents[2]
PACKAGE = ROOT / "polymatch_ros"
RENDERER = PACKAGE / "ros" / "config" / "configs.py"
CONFIG_ROOM = PACKAGE / "ros" / "config"
NAMES = {p.name for table in (AGENT, MONITOR, ROBOT, RECORDER) for p in table}
#: what a mapping of parameters was called when they travelled as a dict
RECEIVERS = re.compile(r"^(p|v|params|values|given|used|config|settings)$")


def argument_strings(source):
    """(line, text) of every string constant that is a ``name:=value`` argument or a piece of
    one (no whitespace: a message that shows the syntax, ``give start:=at``, is prose)."""
    out = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Constant) and isinstance(node.value, str):
            text = node.value
            if ":=" in text and not any(c.isspace() for c in text):
                out.append((node.lineno, text))
    return sorted(out)


def string_key_reads(source, names=NAMES):
    """(line, code) of every ``<params>["name"]`` read of a parameter ``name``, where
    ``<params>`` is a name (or attribute) of the kind that held parameters (``RECEIVERS``)."""
    out = []
    for node in ast.walk(ast.parse(source)):
        if not (isinstance(node, ast.Subscript) and isinstance(node.slice, ast.Constant)
                and node.slice.value in names):
            continue
        holder = node.value
        name = holder.attr if isinstance(holder, ast.Attribute) else getattr(holder, "id", "")
        if RECEIVERS.match(name):
            out.append((node.lineno, ast.unparse(node)))
    return sorted(out)


MODULES = sorted(PACKAGE.rglob("*.py"))
#: where ROS parameters are read: the ROS layer and the commands (the core takes plain values)
ROS_SIDE = sorted(p for p in MODULES if p.is_relative_to(PACKAGE / "ros")
                  or p.is_relative_to(PACKAGE / "cli"))


def test_the_checkers_find_what_they_look_for():
    assert argument_strings('a = ["-p", f"rate:={r}", "-r", "__node:=x"]\n"""doc -p a:=1"""\n'
                            'e = "give start:=at (or leave it out)"') == [
        (1, "__node:=x"), (1, "rate:=")]
    assert string_key_reads('x = self.params["rate"] + values["t_end"] + data["rate"]\n'
                            'y = config.rate + params["topics"]', {"rate", "t_end"}) == [
        (1, "self.params['rate']"), (1, "values['t_end']")]


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(ROOT)))
def test_only_the_renderer_writes_ros_arguments(path):
    if path == RENDERER:
        assert argument_strings(path.read_text(encoding="utf-8"))  # it does write them
        return
    found = argument_strings(path.read_text(encoding="utf-8"))
    assert found == [], f"{path.relative_to(ROOT)}: build the arguments with ros_args: {found}"


@pytest.mark.parametrize("path", [p for p in ROS_SIDE if not p.is_relative_to(CONFIG_ROOM)],
                         ids=lambda p: str(p.relative_to(ROOT)))
def test_no_parameter_is_read_by_a_string_key_outside_the_parameter_room(path):
    found = string_key_reads(path.read_text(encoding="utf-8"))
    assert found == [], f"{path.relative_to(ROOT)}: read the typed configuration: {found}"
