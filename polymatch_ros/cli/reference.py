"""The option reference of docs/guide/commands.md, written from the parser itself.

    python -m polymatch_ros.cli.reference docs/guide/commands.md     # rewrite the reference
    python -m polymatch_ros.cli.reference --check docs/guide/commands.md

The page's text between ``BEGIN`` and ``END`` is replaced by one table per subcommand (every
option, its argument, its help with defaults filled in); ``--check`` exits 1 if the page is
not what the parser says (test/code/test_docs_reference.py runs it in CI).
"""

from __future__ import annotations

import argparse
import sys

from . import NODES, build_parser

BEGIN = "<!-- options: written by `python -m polymatch_ros.cli.reference`; do not edit below -->"
END = "<!-- end of options -->"


def subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    """The subcommands' parsers, in ``--help`` order (argparse has no public accessor)."""
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(action.choices)


def _help(action: argparse.Action, prog: str) -> str:
    text = action.help or ""
    if "%(" in text:
        text = text % dict(vars(action), prog=prog)
    return " ".join(text.split()).replace("|", "\\|")


def _argument(action: argparse.Action) -> str:
    if action.nargs == 0:
        return ""
    if action.choices is not None and not isinstance(action.choices, dict):
        return "\\|".join(str(c) for c in action.choices)
    metavar = action.metavar if action.metavar is not None else action.dest.upper()
    return str(metavar if not isinstance(metavar, tuple) else " ".join(metavar))


def option_table(name: str, parser: argparse.ArgumentParser) -> list[str]:
    """The Markdown table of one subcommand: positional arguments first, then options."""
    rows = [f"### `polymatch {name}`", "", "| argument | value | what it does |",
            "| --- | --- | --- |"]
    for action in parser._actions:
        if isinstance(action, argparse._HelpAction) or action.help == argparse.SUPPRESS:
            continue
        names = ", ".join(action.option_strings) or _argument(action)
        value = _argument(action) if action.option_strings else ""
        rows.append(f"| `{names}` | {f'`{value}`' if value else ''} | "
                    f"{_help(action, parser.prog)} |")
    return rows + [""]


def reference() -> str:
    """Every subcommand's table (the node commands take ROS arguments: see their --help)."""
    lines = [BEGIN, ""]
    for name, parser in subcommands(build_parser()).items():
        if name not in NODES:
            lines += option_table(name, parser)
    return "\n".join(lines + [END])


def rewritten(page: str) -> str:
    """``page`` with its reference section replaced by ``reference()``."""
    if BEGIN not in page or END not in page:
        raise ValueError("the page has no reference section (its BEGIN and END markers)")
    head, _, rest = page.partition(BEGIN)
    _, _, tail = rest.partition(END)
    return head + reference() + tail


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m polymatch_ros.cli.reference",
                                 description=__doc__.splitlines()[0])
    ap.add_argument("page", help="the Markdown page holding the reference section")
    ap.add_argument("--check", action="store_true", help="exit 1 if the page is out of date")
    args = ap.parse_args(argv)
    try:
        with open(args.page, encoding="utf-8") as fh:
            page = fh.read()
        new = rewritten(page)
    except (OSError, ValueError) as exc:
        print(f"reference: {args.page}: {exc}", file=sys.stderr)
        return 2
    if args.check:
        if new != page:
            print(f"reference: {args.page} is out of date: run python -m "
                  f"polymatch_ros.cli.reference {args.page}", file=sys.stderr)
            return 1
        return 0
    with open(args.page, "w", encoding="utf-8") as fh:
        fh.write(new)
    return 0


if __name__ == "__main__":
    sys.exit(main())
