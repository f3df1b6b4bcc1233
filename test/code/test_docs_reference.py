"""The reference pages match the code: docs/guide/commands.md names every option of every
command (checked against argparse's own ``--help`` text, not the page's writer), and the
module table of docs/architecture.md names every module of each wing and no module that is
gone (checked against the files on disk)."""

import pathlib
import re

import pytest

from polymatch_ros.cli import NODES, build_parser
from polymatch_ros.cli.reference import BEGIN, END, rewritten, subcommands

ROOT = pathlib.Path(__file__).resolve().parents[2]
COMMANDS_PAGE = ROOT / "docs" / "guide" / "commands.md"
ARCHITECTURE = ROOT / "docs" / "architecture.md"
PACKAGE = ROOT / "polymatch_ros"
OPTION = re.compile(r"(?<![\w-])(--?[a-zA-Z][a-zA-Z0-9-]*)")
# a module or folder named in a table cell: `name.py`, `name/` or a bare `name`
MODULE = re.compile(r"`([a-z_][a-z0-9_]*)(\.py|/)?`")


def test_the_commands_page_is_what_the_parser_writes():
    page = COMMANDS_PAGE.read_text(encoding="utf-8")
    assert BEGIN in page and END in page
    assert rewritten(page) == page, ("docs/guide/commands.md is out of date: run python -m "
                                     "polymatch_ros.cli.reference docs/guide/commands.md")


@pytest.mark.parametrize("name", [n for n in subcommands(build_parser()) if n not in NODES])
def test_the_commands_page_names_every_option_help_lists(name):
    """Every option string of ``polymatch NAME --help`` appears in NAME's section."""
    page = COMMANDS_PAGE.read_text(encoding="utf-8")
    section = page.split(f"### `polymatch {name}`", 1)[1].split("### ", 1)[0]
    listed = set(OPTION.findall(subcommands(build_parser())[name].format_help()))
    missing = sorted(o for o in listed - {"-h", "--help"}
                     if not re.search(rf"`[^`]*(?<![\w-]){re.escape(o)}(?![\w-])", section))
    assert listed and not missing, f"polymatch {name}: not in commands.md: {missing}"


def wing_rows() -> dict[str, tuple[set[str], set[str]]]:
    """The module table of docs/architecture.md: wing folder -> (the names its row gives as
    files or folders, ``x.py`` or ``x/``; the bare names, ``x``, modules or commands)."""
    rows = {}
    for line in ARCHITECTURE.read_text(encoding="utf-8").splitlines():
        cells = [c.strip() for c in re.split(r"(?<!\\)\|", line.strip().strip("|"))]
        if len(cells) == 2 and re.fullmatch(r"`[a-z_/]+/`", cells[0]):
            found = MODULE.findall(cells[1])
            rows[cells[0].strip("`").rstrip("/")] = ({m for m, suffix in found if suffix},
                                                     {m for m, suffix in found if not suffix})
    return rows


def modules_on_disk(wing: str) -> set[str]:
    folder = PACKAGE / wing
    files = {p.stem for p in folder.glob("*.py") if p.name not in ("__init__.py", "__main__.py")}
    return files | {p.name for p in folder.iterdir() if (p / "__init__.py").exists()}


def test_the_architecture_table_has_a_row_for_every_wing():
    wings = {str(p.parent.relative_to(PACKAGE)) for p in PACKAGE.rglob("__init__.py")
             if p.parent != PACKAGE}
    assert set(wing_rows()) == wings - {"ros"}, sorted(wings)


@pytest.mark.parametrize("wing", sorted(wing_rows()))
def test_the_architecture_table_names_every_module_of_a_wing_and_no_other(wing):
    (files, bare), on_disk = wing_rows()[wing], modules_on_disk(wing)
    left_out = sorted(on_disk - files - bare)
    assert not left_out, f"{wing}/: modules the table leaves out: {left_out}"
    gone = sorted(files - on_disk - {"__init__"})
    assert not gone, f"{wing}/: the table names modules that do not exist: {gone}"
