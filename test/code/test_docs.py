"""The docs stay true to the code: every relative link in README.md and docs/ resolves (file
and heading), every `polymatch` subcommand they show exists and answers ``--help``, and every
option they name is one of that subcommand's options."""

import contextlib
import io
import pathlib
import re

import pytest

from polymatch_ros.cli import NODES, build_parser
from polymatch_ros.cli.reference import subcommands

ROOT = pathlib.Path(__file__).resolve().parents[2]
PAGES = sorted([ROOT / "README.md", *(ROOT / "docs").rglob("*.md")])
LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")
# `polymatch SUB ...` at the start of an inline code span or of a code block's line
COMMAND = re.compile(r"^(?:\$ )?(?:\.venv/bin/)?polymatch ([a-z][a-z0-9_-]*)(.*)$", re.M)
OPTION = re.compile(r"(?<![\w-])(--[a-z][a-z0-9-]*)")
# options that belong to ROS, not to argparse (`polymatch agent --ros-args -p ...`)
NOT_ARGPARSE = {"--ros-args", "--params-file"}


def slug(heading: str) -> str:
    """GitHub's anchor of a Markdown heading: lower case, punctuation dropped, spaces to '-'."""
    text = re.sub(r"[`*_]", "", heading.strip().lower())
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors(page: pathlib.Path) -> set[str]:
    text = re.sub(r"```.*?```", "", page.read_text(encoding="utf-8"), flags=re.S)
    return {slug(h) for h in re.findall(r"^#+ (.+)$", text, re.M)}


def relative_links(page: pathlib.Path) -> list[str]:
    text = re.sub(r"```.*?```", "", page.read_text(encoding="utf-8"), flags=re.S)
    return [t for t in LINK.findall(text) if not re.match(r"[a-z]+:", t)]


def test_slug_follows_github_anchors():
    assert slug("Several hosts") == "several-hosts"
    assert slug("`polymatch run`: the options") == "polymatch-run-the-options"
    assert slug("Lockstep (exact)") == "lockstep-exact"


@pytest.mark.parametrize("page", PAGES, ids=[str(p.relative_to(ROOT)) for p in PAGES])
def test_every_relative_link_resolves_to_a_file_and_heading(page):
    broken = []
    for target in relative_links(page):
        path, _, anchor = target.partition("#")
        dest = (page.parent / path).resolve() if path else page
        if not dest.exists():
            broken.append(f"{target} (no such file)")
        elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
            broken.append(f"{target} (no heading #{anchor} in {dest.name})")
    assert not broken, f"{page.relative_to(ROOT)}: " + "; ".join(broken)


def code(page: pathlib.Path) -> str:
    """The page's code: its code blocks and inline code spans, one per line."""
    text = page.read_text(encoding="utf-8")
    blocks = re.findall(r"```[a-z]*\n(.*?)```", text, re.S)
    spans = re.findall(r"`([^`\n]+)`", re.sub(r"```.*?```", "", text, flags=re.S))
    return "\n".join(blocks + spans)


def shown_commands() -> list[tuple[str, str, str]]:
    """(page, subcommand, rest of the line) of every `polymatch SUB ...` the docs show."""
    found = []
    for page in PAGES:
        for sub, rest in COMMAND.findall(code(page)):
            found.append((str(page.relative_to(ROOT)), sub, rest))
    return found


def subparsers() -> dict:
    return subcommands(build_parser())


def test_the_docs_show_commands_and_the_check_sees_them():
    subs = {sub for _, sub, _ in shown_commands()}
    assert {"run", "simulate", "explain", "sweep", "echo", "set"} <= subs


def test_every_subcommand_the_docs_show_exists_and_answers_help():
    parsers = subparsers()
    unknown = sorted({f"{page}: polymatch {sub}" for page, sub, _ in shown_commands()
                      if sub not in parsers})
    assert not unknown, "the docs show subcommands that do not exist: " + "; ".join(unknown)
    for sub in sorted({sub for _, sub, _ in shown_commands()} - set(NODES)):
        out = io.StringIO()
        with contextlib.redirect_stdout(out), pytest.raises(SystemExit) as ended:
            build_parser().parse_args([sub, "--help"])
        assert ended.value.code == 0 and f"polymatch {sub}" in out.getvalue(), sub


def test_every_option_the_docs_name_exists():
    helps = {name: p.format_help() for name, p in subparsers().items()}
    missing = []
    for page, sub, rest in shown_commands():
        if sub in NODES or sub not in helps:
            continue
        for option in OPTION.findall(rest):
            if option not in NOT_ARGPARSE and not re.search(rf"(?<![\w-]){option}(?![\w-])",
                                                          helps[sub]):
                missing.append(f"{page}: polymatch {sub} {option}")
    assert not missing, ("options the docs name that do not exist: "
                         + "; ".join(sorted(set(missing))))


def test_the_option_check_catches_a_missing_option():
    helps = subparsers()["run"].format_help()
    assert "--on-failure" in helps and "--no-such-option" not in helps
