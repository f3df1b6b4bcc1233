"""The foreign agent of test/ros/test_public_protocol.py is written from the protocol alone: it
imports rclpy, numpy, scipy, yaml and the interface package, nothing of ``polymatch_ros``."""

import ast
import os

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
FOREIGN = os.path.join(REPO, "test", "support", "foreign_agent.py")


def _imports(path):
    """The top-level names of every module ``path`` imports."""
    with open(path) as fh:
        tree = ast.parse(fh.read())
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            names.add((node.module or "").split(".")[0])
    return names


def test_the_foreign_agent_uses_only_the_public_interfaces():
    assert _imports(FOREIGN) <= {"array", "sys", "time", "numpy", "rclpy", "yaml", "scipy",
                                 "polymatch_interfaces"}
