"""package.xml declares what the code imports: rosdep installs a node's dependencies from its
``exec_depend`` keys, so a missing key is a node that fails on a ROS machine."""

import ast
import importlib.metadata
import pathlib
import sys
import sysconfig
import xml.etree.ElementTree as ET

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
PACKAGE = ROOT / "polymatch_ros"

# Python distributions by their rosdep keys; every other import is a ROS package of that name.
ROSDEP_KEYS = {"numpy": "python3-numpy", "scipy": "python3-scipy", "yaml": "python3-yaml",
               "matplotlib": "python3-matplotlib",
               # rosdep's pip key mcap-ros2-support installs both mcap_ros2 and mcap
               "mcap": "mcap-ros2-support", "mcap_ros2": "mcap-ros2-support"}


def imported_top_level_names():
    """The first name of every absolute import in polymatch_ros/, the standard library's and
    the package's own left out."""
    names = set()
    for path in PACKAGE.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                names.update(alias.name.split(".")[0] for alias in node.names)
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names.add(node.module.split(".")[0])
    return names - set(sys.stdlib_module_names) - {"polymatch_ros", "__future__"}


def declared(tag):
    return {element.text for element in ET.parse(ROOT / "package.xml").getroot().iter(tag)}


def test_every_import_is_an_exec_depend_and_every_exec_depend_is_imported():
    wanted = {ROSDEP_KEYS.get(name, name) for name in imported_top_level_names()}
    assert declared("exec_depend") == wanted


def test_the_import_scan_sees_ros_and_python_dependencies():
    names = imported_top_level_names()
    assert {"rclpy", "std_srvs", "nav_msgs", "numpy", "scipy"} <= names
    assert "os" not in names and "polymatch_ros" not in names


def test_test_tools_are_test_depends():
    assert {"python3-pytest", "python3-hypothesis"} <= declared("test_depend")


def test_pip_puts_only_polymatch_on_the_path():
    """pip (a wheel) installs one console script; the node executables are colcon's, in
    lib/polymatch_ros (the colcon test checks them), and ``polymatch agent|monitor|robot``."""
    purelib = sysconfig.get_paths()["purelib"]
    installed = [d for d in importlib.metadata.distributions(path=[purelib])
                 if d.metadata["Name"] == "polymatch_ros"]
    if not installed:
        pytest.skip("polymatch_ros is not pip-installed in this interpreter")
    scripts = {e.name for e in installed[0].entry_points if e.group == "console_scripts"}
    assert scripts == {"polymatch"}
