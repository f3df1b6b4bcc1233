"""Size rules, as lines: a module holds one concept (about 400 lines, at most 600), a function
at most 60.  They cover the package and the benchmarks beside it.  A folder of either is a room
of at most 15 modules (its ``__init__`` and ``__main__`` aside); a larger one splits into rooms.

A function's length is ``end_lineno - lineno + 1`` of its ``def`` (docstring and body, no
decorators); nested functions and methods count on their own as well as inside their parent.
"""

import ast
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
MODULE_LINES = 600
FUNCTION_LINES = 60
FOLDER_MODULES = 15
TREES = ("polymatch_ros", "benchmarks")


def long_functions(source, limit=FUNCTION_LINES):
    """(name, first line, lines) of every function in ``source`` longer than ``limit`` lines."""
    return [(node.name, node.lineno, node.end_lineno - node.lineno + 1)
            for node in ast.walk(ast.parse(source))
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
            and node.end_lineno - node.lineno + 1 > limit]


MODULES = sorted(p for tree in TREES for p in (ROOT / tree).rglob("*.py"))


def test_both_trees_have_modules():
    for tree in TREES:
        assert any(p.is_relative_to(ROOT / tree) for p in MODULES), f"{tree}/ has no modules"


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(ROOT)))
def test_module_is_at_most_600_lines(path):
    lines = len(path.read_text(encoding="utf-8").splitlines())
    assert lines <= MODULE_LINES, f"{path.relative_to(ROOT)}: {lines} lines"


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(ROOT)))
def test_functions_are_at_most_60_lines(path):
    found = long_functions(path.read_text(encoding="utf-8"))
    assert not found, "; ".join(f"{path.relative_to(ROOT)}:{line} {name} ({n} lines)"
                                for name, line, n in found)


FOLDERS = sorted(p.parent for tree in TREES for p in (ROOT / tree).rglob("__init__.py"))


@pytest.mark.parametrize("folder", FOLDERS, ids=lambda p: str(p.relative_to(ROOT)))
def test_a_folder_holds_at_most_15_modules(folder):
    modules = [p for p in folder.glob("*.py") if p.name not in ("__init__.py", "__main__.py")]
    assert len(modules) <= FOLDER_MODULES, f"{folder.relative_to(ROOT)}: {len(modules)} modules"


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
