"""The package's layers, as imports: core is pure numerics, ros is a thin layer on it, the bench
only measures, and cli only parses and dispatches.

Every import statement counts, the lazy ones inside functions included.
"""

import ast
import pathlib

import pytest

PACKAGE = pathlib.Path(__file__).resolve().parent.parent / "polymatch_ros"
ROS_PREFIXES = ("rclpy", "rcl_", "rcutils", "rmw", "rosidl", "builtin_interfaces", "launch")
ROS_SUFFIXES = ("_msgs", "_srvs", "_interfaces")


def module_name(path):
    rel = path.relative_to(PACKAGE.parent).with_suffix("")
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


MODULES = sorted(PACKAGE.rglob("*.py"))


def layer_modules(layer):
    return [p for p in MODULES if within(module_name(p), layer)]


def test_package_has_the_four_layers():
    for layer in ("polymatch_ros.core", "polymatch_ros.ros", "polymatch_ros.bench"):
        assert layer_modules(layer), f"{layer} is missing"
    assert (PACKAGE / "cli.py").is_file()


@pytest.mark.parametrize("path", layer_modules("polymatch_ros.core"), ids=lambda p: p.name)
def test_core_imports_no_ros_and_no_upper_layer(path):
    bad = sorted(n for n in imports_of(path)
                 if is_ros(n) or any(within(n, f"polymatch_ros.{up}")
                                     for up in ("ros", "bench", "cli", "console", "figures")))
    assert not bad, f"{module_name(path)} imports {bad}"


@pytest.mark.parametrize("path", layer_modules("polymatch_ros.ros"), ids=lambda p: p.name)
def test_ros_layer_imports_neither_cli_nor_bench(path):
    bad = sorted(n for n in imports_of(path)
                 if within(n, "polymatch_ros.cli") or within(n, "polymatch_ros.bench"))
    assert not bad, f"{module_name(path)} imports {bad}"


@pytest.mark.parametrize("path", MODULES, ids=lambda p: module_name(p))
def test_nothing_imports_cli_and_only_cli_reaches_bench(path):
    name = module_name(path)
    found = imports_of(path)
    assert not any(within(n, "polymatch_ros.cli") for n in found), f"{name} imports cli"
    if not (within(name, "polymatch_ros.bench") or name == "polymatch_ros.cli"):
        assert not any(within(n, "polymatch_ros.bench") for n in found), f"{name} imports bench"


def test_the_rules_catch_a_violation(tmp_path):
    """The checker itself: a core module importing rclpy or the ros layer is seen."""
    probe = tmp_path / "probe.py"
    probe.write_text(
        "def f():\n    import rclpy\n    from ..ros import wire\n    return rclpy, wire\n")
    found = imports_of(probe, "polymatch_ros.core.probe")
    assert any(is_ros(n) for n in found)
    assert "polymatch_ros.ros.wire" in found
