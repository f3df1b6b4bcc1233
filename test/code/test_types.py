"""Typed API: the package passes mypy under ``mypy.ini``, and every public function and method
of ``polymatch_ros/core``, ``polymatch_ros/ros`` and ``polymatch_ros/cli`` annotates all its
parameters and its return.

Public means a name not starting with ``_``; ``__init__`` and ``__call__`` count as public.
``self`` and ``cls`` (the first parameter of a method) need no annotation.
"""

import ast
import importlib.util
import pathlib
import subprocess
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
CONFIG = ROOT / "mypy.ini"
TYPED_TREES = ("polymatch_ros/core", "polymatch_ros/ros", "polymatch_ros/cli")
PUBLIC_DUNDERS = frozenset({"__init__", "__call__"})
MYPY_TIMEOUT_S = 300


def _is_public(name):
    return name in PUBLIC_DUNDERS or not name.startswith("_")


def _missing(function, is_method):
    """What ``function`` leaves unannotated: parameter names, and ``return``."""
    args = function.args
    positional = args.posonlyargs + args.args
    if is_method and positional and positional[0].arg in ("self", "cls"):
        positional = positional[1:]
    params = positional + args.kwonlyargs + [a for a in (args.vararg, args.kwarg) if a]
    missing = [a.arg for a in params if a.annotation is None]
    if function.returns is None:
        missing.append("return")
    return missing


def _walk(body, scope, is_class, found):
    """Collect (qualified name, line, missing) for public functions in ``body``; nested
    functions inside a function body are its own business and are not visited."""
    for node in body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            if _is_public(node.name):
                missing = _missing(node, is_class)
                if missing:
                    found.append((f"{scope}{node.name}", node.lineno, missing))
        elif isinstance(node, ast.ClassDef) and _is_public(node.name):
            _walk(node.body, f"{scope}{node.name}.", True, found)
        elif isinstance(node, (ast.If, ast.Try)):
            _walk(node.body + node.orelse, scope, is_class, found)


def unannotated(source):
    """(qualified name, line, missing annotations) of every public function in ``source``
    that lacks an annotation on a parameter (besides ``self``/``cls``) or on its return."""
    found = []
    _walk(ast.parse(source).body, "", False, found)
    return found


TYPED_MODULES = sorted(p for tree in TYPED_TREES for p in (ROOT / tree).rglob("*.py"))


def test_typed_trees_have_modules():
    for tree in TYPED_TREES:
        assert any(p.is_relative_to(ROOT / tree) for p in TYPED_MODULES), f"{tree}/ is empty"


def test_public_functions_are_annotated():
    offenders = []
    for path in TYPED_MODULES:
        for name, line, missing in unannotated(path.read_text(encoding="utf-8")):
            offenders.append(f"{path.relative_to(ROOT)}:{line} {name}: {', '.join(missing)}")
    assert not offenders, (f"{len(offenders)} public functions lack annotations:\n"
                           + "\n".join(offenders))


def test_the_annotation_check_catches_omissions():
    """The checker itself: a bare function, a method missing a parameter or return annotation,
    and an unannotated ``__init__`` are caught; private helpers, ``self`` and a fully annotated
    function are not."""
    source = (
        "def bare(a, b=1):\n    return a\n"
        "def typed(a: int, *rest: str, key: float = 1.0, **more: int) -> int:\n    return a\n"
        "def _private(a):\n    return a\n"
        "class Thing:\n"
        "    def __init__(self, size):\n        self.size = size\n"
        "    def grow(self, by: int):\n        return by\n"
        "    def shrink(self, by) -> int:\n        return by\n"
        "    @classmethod\n"
        "    def make(cls) -> 'Thing':\n        return cls(1)\n"
        "    def __repr__(self):\n        return 'Thing'\n"
    )
    assert unannotated(source) == [
        ("bare", 1, ["a", "b", "return"]),
        ("Thing.__init__", 8, ["size", "return"]),
        ("Thing.grow", 10, ["return"]),
        ("Thing.shrink", 12, ["by"]),
    ]


def test_mypy_passes():
    if importlib.util.find_spec("mypy") is None:
        pytest.skip("mypy is not installed (pip install -r requirements.txt)")
    try:
        result = subprocess.run(
            [sys.executable, "-m", "mypy", "--config-file", str(CONFIG)],
            cwd=ROOT, capture_output=True, text=True, timeout=MYPY_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        pytest.fail(f"mypy did not finish within {MYPY_TIMEOUT_S} s")
    assert result.returncode == 0, f"mypy failed:\n{result.stdout}{result.stderr}"
