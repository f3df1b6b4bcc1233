"""The package's size rules, as lines: modules at most 400 lines, functions at most 60.

A function's length is ``end_lineno - lineno + 1`` of its ``def`` (docstring and body, no
decorators); nested functions and methods count on their own as well as inside their parent.
"""

import ast
import pathlib

import pytest

PACKAGE = pathlib.Path(__file__).resolve().parent.parent / "polymatch_ros"
MODULE_LINES = 400
FUNCTION_LINES = 60
LAYERS = ("core", "ros", "bench")


def long_functions(source, limit=FUNCTION_LINES):
    """(name, first line, lines) of every function in ``source`` longer than ``limit`` lines."""
    return [(node.name, node.lineno, node.end_lineno - node.lineno + 1)
            for node in ast.walk(ast.parse(source))
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
            and node.end_lineno - node.lineno + 1 > limit]


def layer_modules(layer):
    """The layer's modules, all of them under the function limit."""
    return sorted((PACKAGE / layer).rglob("*.py"))


def test_every_layer_has_modules():
    for layer in LAYERS:
        assert layer_modules(layer), f"polymatch_ros/{layer} has no modules"


@pytest.mark.parametrize("path", sorted(PACKAGE.rglob("*.py")),
                         ids=lambda p: str(p.relative_to(PACKAGE)))
def test_module_is_at_most_400_lines(path):
    lines = len(path.read_text(encoding="utf-8").splitlines())
    assert lines <= MODULE_LINES, f"{path.relative_to(PACKAGE)}: {lines} lines"


@pytest.mark.parametrize("path", [p for layer in LAYERS for p in layer_modules(layer)],
                         ids=lambda p: str(p.relative_to(PACKAGE)))
def test_functions_are_at_most_60_lines(path):
    found = long_functions(path.read_text(encoding="utf-8"))
    assert not found, "; ".join(f"{path.relative_to(PACKAGE)}:{line} {name} ({n} lines)"
                                for name, line, n in found)


def _function(name, lines, indent=""):
    """Source of a function ``lines`` long (its ``def`` line included)."""
    body = [f"{indent}    x = {i}" for i in range(lines - 2)]
    return "\n".join([f"{indent}def {name}():"] + body + [f"{indent}    return x"]) + "\n"


def test_the_limit_is_exact():
    """The checker itself: 60 lines pass, a 61-line function or method is caught."""
    assert long_functions(_function("fits", 60)) == []
    assert long_functions(_function("too_long", 61)) == [("too_long", 1, 61)]
    method = "class C:\n" + _function("too_long", 61, indent="    ")
    assert long_functions(method) == [("too_long", 2, 61)]
