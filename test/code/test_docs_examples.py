"""The docs' examples run as written: every YAML block in README.md and docs/ loads as a scene
(a block marked ``<!-- fragment of SCENE [with N agents][, one per line] -->`` loads inside the
shipped scene SCENE), and every shell line of a code block that runs ``polymatch`` parses.

The oracle is the scene loader and the command-line parser the user runs: a block or a line
that they refuse is an example that would fail in the user's hands."""

import contextlib
import copy
import io
import pathlib
import re
import shlex

import pytest
import yaml

from polymatch_ros.cli import NODES, build_parser
from polymatch_ros.core.errors import PolymatchError
from polymatch_ros.core.scenes.scene import load_scene, resolve_scene_path

ROOT = pathlib.Path(__file__).resolve().parents[2]
PAGES = sorted([ROOT / "README.md", *(ROOT / "docs").rglob("*.md")])
YAML_BLOCK = re.compile(r"(?:<!-- fragment of (\w+)( with (\d+) agents)?(, one per line)? -->\n)?"
                        r"```yaml\n(.*?)```", re.S)
SHELL = ("bash", "sh", "shell", "console", "")
# a command's start inside a shell line: at its beginning or after && || ; |
POLYMATCH = re.compile(r"(?:^|&&|\|\||;|\|)\s*(?:\$ )?(?:\.venv/bin/)?polymatch\s+([^&|;]*)")


def yaml_examples() -> list[tuple[str, str, dict]]:
    """(page:line, what, scene data) of every YAML block, fragments merged into their scene."""
    found = []
    for page in PAGES:
        text = page.read_text(encoding="utf-8")
        for m in YAML_BLOCK.finditer(text):
            scene, _, agents, per_line, body = m.groups()
            where = f"{page.relative_to(ROOT)}:{text.count(chr(10), 0, m.start(5)) + 1}"
            if scene is None:
                found.append((where, "scene", yaml.safe_load(body)))
                continue
            base = yaml.safe_load(pathlib.Path(resolve_scene_path(scene)).read_text())
            if agents:
                base["groups"][0]["count"] = int(agents)
            parts = [ln for ln in body.splitlines() if ln.strip()] if per_line else [body]
            for part in parts:
                found.append((where, part.strip()[:60], {**copy.deepcopy(base),
                                                         **yaml.safe_load(part)}))
    return found


def fenced_blocks(text: str) -> list[tuple[str, int, list[str]]]:
    """(language, line number of the block's first line, lines) of every fenced code block."""
    blocks: list[tuple[str, int, list[str]]] = []
    lang, first, body = None, 0, []
    for number, line in enumerate(text.splitlines(), 1):
        if line.startswith("```"):
            if lang is None:
                lang, first, body = line[3:].strip(), number + 1, []
            else:
                blocks.append((lang, first, body))
                lang = None
        elif lang is not None:
            body.append(line)
    return blocks


def shell_commands() -> list[tuple[str, list[str]]]:
    """(page:line, argv after ``polymatch``) of every command a shell block's line runs (a
    block marked bash, sh, shell or console, or one without a language)."""
    found = []
    for page in PAGES:
        for lang, first, body in fenced_blocks(page.read_text(encoding="utf-8")):
            if lang not in SHELL:
                continue
            for k, line in enumerate(body):
                line = re.sub(r"\s+#.*$", "", line)
                for command in POLYMATCH.findall(line):
                    found.append((f"{page.relative_to(ROOT)}:{first + k}",
                                  shlex.split(command.split(">")[0])))
    return found


EXAMPLES = yaml_examples()
COMMANDS = shell_commands()


def test_the_docs_have_examples_and_the_checks_see_them():
    assert len(EXAMPLES) >= 10 and len(COMMANDS) >= 8, (len(EXAMPLES), len(COMMANDS))
    assert any(what == "scene" for _, what, _ in EXAMPLES)
    assert any(argv[:1] == ["simulate"] for _, argv in COMMANDS)   # README's set-up line


@pytest.mark.parametrize("where,what,data", EXAMPLES,
                         ids=[f"{w} {what}" for w, what, _ in EXAMPLES])
def test_every_yaml_block_of_the_docs_loads_as_a_scene(where, what, data):
    try:
        load_scene(data)
    except PolymatchError as exc:
        pytest.fail(f"{where}: {what}: {exc}")


def _parse(argv: list[str]) -> str:
    """'' if ``polymatch ARGV`` parses, else the parser's one-line error."""
    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            build_parser().parse_args(argv)
    except SystemExit as ended:
        if ended.code:
            return (err.getvalue().strip().splitlines() or ["exit " + str(ended.code)])[-1]
    return ""


@pytest.mark.parametrize("where,argv", COMMANDS, ids=[w for w, _ in COMMANDS])
def test_every_shell_line_of_the_docs_that_runs_polymatch_parses(where, argv):
    if argv and argv[0] in NODES:       # the nodes take ROS arguments, not argparse's
        return
    error = _parse(argv)
    assert not error, f"{where}: polymatch {' '.join(argv)}: {error}"


def test_the_checks_catch_a_broken_example():
    """A scene key the loader refuses and a line the parser refuses are both seen."""
    data = yaml.safe_load(pathlib.Path(resolve_scene_path("congruent_triangles")).read_text())
    data["groups"][0]["velocities"] = {"centroid": "zero"}        # first order: refused
    with pytest.raises(PolymatchError, match="order"):
        load_scene(data)
    assert "invalid choice" in _parse(["run", "congruent_triangles", "--mode", "warp"])
    assert _parse(["run", "congruent_triangles", "--mode", "realtime"]) == ""
