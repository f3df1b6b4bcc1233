r"""The package's layers, as imports: arrows run one way and no module reaches itself.

    cli -> ros.supervisor ---------------------> ros.network -> ros.process -> ros.wire -> core
                          \-> ros.config ----------------------------------/
           ros.nodes -> ros.agents -> ros.config, ros.process -> ros.wire -> core

The supervisor imports no node and no agent module: what it shares with the processes it starts
(the checkpoint format, control commands, reading the exchange, the parameter table, the process
shell, the environment) lives in the rooms below both.

``core`` is pure numerics (no ROS import); ``console`` and ``figures`` serve the commands and
the supervisor's summary; nothing outside ``cli`` imports ``cli``; nothing in the package
imports the benchmarks (``benchmarks/``, beside the package, not installed).  Every import
statement counts, the lazy ones inside functions included.
"""

import ast
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
PACKAGE = ROOT / "polymatch_ros"
ROS_PREFIXES = ("rclpy", "rcl_", "rcutils", "rmw", "rosidl", "builtin_interfaces", "launch",
                "ament_")
ROS_SUFFIXES = ("_msgs", "_srvs", "_interfaces")

#: each layer, and the layers of the package it may import (besides itself)
ALLOWED = {
    "polymatch_ros.core": (),
    "polymatch_ros.console": ("polymatch_ros.core",),
    "polymatch_ros.figures": ("polymatch_ros.core",),
    "polymatch_ros.ros.wire": ("polymatch_ros.core",),
    "polymatch_ros.ros.process": ("polymatch_ros.ros.wire", "polymatch_ros.core"),
    "polymatch_ros.ros.config": ("polymatch_ros.ros.wire", "polymatch_ros.core"),
    "polymatch_ros.ros.network": ("polymatch_ros.ros.process", "polymatch_ros.ros.wire",
                                  "polymatch_ros.core"),
    "polymatch_ros.ros.agents": ("polymatch_ros.ros.config", "polymatch_ros.ros.process",
                                 "polymatch_ros.ros.wire", "polymatch_ros.core"),
    "polymatch_ros.ros.nodes": ("polymatch_ros.ros.agents", "polymatch_ros.ros.config",
                                "polymatch_ros.ros.process", "polymatch_ros.ros.wire",
                                "polymatch_ros.core"),
    "polymatch_ros.ros.supervisor": ("polymatch_ros.ros.config", "polymatch_ros.ros.network",
                                     "polymatch_ros.ros.process", "polymatch_ros.ros.wire",
                                     "polymatch_ros.core", "polymatch_ros.console"),
    "polymatch_ros.cli": ("polymatch_ros",),
}
#: package modules that hold no code of a layer (docstrings only)
NEUTRAL = {"polymatch_ros", "polymatch_ros.ros"}


def module_name(path, package=PACKAGE):
    rel = path.relative_to(package.parent).with_suffix("")
    parts = rel.parts[:-1] if rel.name == "__init__" else rel.parts
    return ".".join(parts)


def imports_of(path, name=None):
    """Absolute names of every module `path` (module `name`) imports, relative ones resolved."""
    package = (name or module_name(path)).split(".")
    if path.name != "__init__.py":
        package = package[:-1]
    names = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = package[:len(package) - node.level + 1] if node.level else []
            stem = ".".join(base + ([node.module] if node.module else []))
            names.add(stem)
            names.update(f"{stem}.{alias.name}" for alias in node.names)
    return names


def is_ros(name):
    top = name.split(".")[0]
    return top.startswith(ROS_PREFIXES) or top.endswith(ROS_SUFFIXES)


def within(name, layer):
    return name == layer or name.startswith(layer + ".")


def layer_of(name):
    """The longest layer of ``ALLOWED`` that holds module ``name`` (None: neutral)."""
    found = [layer for layer in ALLOWED if within(name, layer)]
    return max(found, key=len) if found else None


MODULES = sorted(PACKAGE.rglob("*.py"))
NAMES = {module_name(p): p for p in MODULES}


def package_imports(path):
    """The package's own modules that ``path`` imports (names of modules, not attributes)."""
    return {n for n in imports_of(path) if n in NAMES}


def test_every_module_has_a_layer_and_every_layer_has_modules():
    assert all(layer_of(n) or n in NEUTRAL for n in NAMES), \
        sorted(n for n in NAMES if not layer_of(n) and n not in NEUTRAL)
    for layer in ALLOWED:
        assert any(layer_of(n) == layer for n in NAMES), f"{layer} is missing"


@pytest.mark.parametrize("path", MODULES, ids=lambda p: module_name(p))
def test_imports_run_down_the_layers_only(path):
    name = module_name(path)
    own = layer_of(name)
    if own is None:
        return
    bad = sorted(n for n in package_imports(path)
                 if layer_of(n) not in (own, None)
                 and not any(within(n, allowed) for allowed in ALLOWED[own]))
    assert not bad, f"{name} ({own}) imports {bad}"


@pytest.mark.parametrize("path", [p for p in MODULES if layer_of(module_name(p))
                                  == "polymatch_ros.core"], ids=lambda p: module_name(p))
def test_core_imports_no_ros(path):
    bad = sorted(n for n in imports_of(path) if is_ros(n))
    assert not bad, f"{module_name(path)} imports {bad}"


@pytest.mark.parametrize("path", MODULES, ids=lambda p: module_name(p))
def test_the_package_never_imports_the_benchmarks_or_the_tests(path):
    bad = sorted(n for n in imports_of(path) if n.split(".")[0] in ("benchmarks", "test"))
    assert not bad, f"{module_name(path)} imports {bad}"


def import_cycles(graph):
    """Strongly connected components of more than one module (Tarjan), each sorted."""
    index, low, stack, on, cycles = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                cycles.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return cycles


def test_no_import_circle_anywhere_in_the_package():
    """A package ``__init__`` re-exporting its own modules is not a circle: its modules'
    imports of the package itself are left out (they name a sibling)."""
    graph = {}
    for name, path in NAMES.items():
        graph[name] = {n for n in package_imports(path)
                       if not (path.name != "__init__.py" and name.startswith(n + "."))}
    assert import_cycles(graph) == []


def test_the_rules_catch_a_violation(tmp_path):
    """The checkers themselves: an upward arrow, a ROS import in core and a circle are seen."""
    probe = tmp_path / "probe.py"
    probe.write_text(
        "def f():\n    import rclpy\n    from ..ros import wire\n    return rclpy, wire\n")
    found = imports_of(probe, "polymatch_ros.core.probe")
    assert any(is_ros(n) for n in found)
    assert "polymatch_ros.ros.wire" in found
    assert not any(within("polymatch_ros.ros.wire", a) for a in ALLOWED["polymatch_ros.core"])
    assert layer_of("polymatch_ros.ros.nodes.agent") == "polymatch_ros.ros.nodes"
    assert import_cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert import_cycles({"a": {"b"}, "b": set()}) == []
