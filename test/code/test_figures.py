"""Measured figures live in the benchmark reports (docs/bench/), not in the code: no comment or
docstring of the package, the benchmarks or the tests quotes one.  A comment that needs a
figure names the report that holds it.

A measured figure is a number with a rate or size unit (lockstep rounds a second,
CPU-seconds, decimal megabytes; a step rate is also a setting), a speed-up ("N x faster"), a
share of a time ("N% of its time"), or a duration that something took ("took N s", "~N ms").
Constants, limits and input formats (an interval, a bound, binary units) are not figures."""

import ast
import io
import pathlib
import re
import tokenize

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
SOURCES = sorted(p for folder in ("polymatch_ros", "benchmarks", "test")
                 for p in (ROOT / folder).rglob("*.py"))
#: modules whose comments may quote measured figures (none)
KEPT: set[str] = set()

_NUM = r"(?<![\w.])\d[\d,]*(?:\.\d+)?"
_DURATION = r"(?:ms|µs|us|s|seconds?|minutes?)\b"
FIGURE = re.compile("|".join([
    _NUM + r"\s*(?:rounds?/s|CPU[- ]s(?:econds)?\b|MB\b|kB\b|GB\b)",
    _NUM + r"\s*(?:x|times) (?:faster|slower)",
    _NUM + r"\s*% of [\w' -]{0,30}?\b(?:time|round|CPU|core)",
    r"\b(?:took|takes|cost|costs|spent|spends|lasts|lasted|measured:?)\s+(?:about\s+|~)?"
    + _NUM + r"\s*" + _DURATION,
    r"~\d[\d,]*(?:\.\d+)?\s*" + _DURATION,
]))


def prose(source: str) -> list[tuple[int, str]]:
    """(line, text) of every comment and docstring line of a module's source."""
    out = [(t.start[0], t.string) for t in tokenize.generate_tokens(io.StringIO(source).readline)
           if t.type == tokenize.COMMENT]
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, (ast.Module, ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            doc = ast.get_docstring(node, clean=False)
            if doc:
                out += [(node.body[0].lineno + i, line) for i, line in enumerate(doc.splitlines())]
    return sorted(out)


def figures(source: str) -> list[str]:
    """'line: figure' for each measured figure the comments and docstrings quote."""
    return [f"{line}: {m.group(0)}" for line, text in prose(source)
            for m in FIGURE.finditer(text)]


@pytest.mark.parametrize("path", SOURCES, ids=lambda p: str(p.relative_to(ROOT)))
def test_no_comment_or_docstring_quotes_a_measured_figure(path):
    if str(path.relative_to(ROOT)) in KEPT:
        pytest.skip("kept")
    found = figures(path.read_text(encoding="utf-8"))
    assert not found, (f"{path.relative_to(ROOT)} quotes measured figures {found}: name the "
                       "report under docs/bench that holds them instead")


QUOTED = '''
"""Packing: one process made 423 rounds/s at 1024 agents."""
# a record of 1024 agents is 0.55 MB, and the monitor used 1.1 CPU-s a second
def f():
    """The pruned search is 5x faster; the flood took 44% of a lockstep agent's time."""
    x = 1  # the solve took 12 ms, and the import ~0.8 s
'''

CONSTANTS = '''
"""--memory-limit: 1.5 GiB, 300 MiB, 12 KiB; a heartbeat every 100 ms."""
# drop 10% of what host 1 receives; the kill at 30% of it on the progress lines
def f():
    """Every wait is bounded (60 s); the < 4 ms target; the DDS lease is 10 s."""
    x = "took 12 ms"   # a message the code prints is not a comment
'''


def test_the_check_catches_quoted_figures_and_passes_constants():
    assert [f.split(": ", 1)[1] for f in figures(QUOTED)] == [
        "423 rounds/s", "0.55 MB", "1.1 CPU-s", "5x faster", "44% of a lockstep agent's time",
        "took 12 ms", "~0.8 s"]
    assert figures(CONSTANTS) == []
