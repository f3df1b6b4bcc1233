"""The markdown tables a benchmark family prints, read back as rows of named cells."""

import re

ROW = re.compile(r"^\|(.*)\|\s*$")
RULE = re.compile(r"^\|[-| :]+\|\s*$")


def family_tables(text):
    """Every table in ``text``: a list of (header names, rows), a row a dict name -> cell."""
    tables, lines = [], text.splitlines()
    for i in range(1, len(lines)):
        if RULE.match(lines[i]) and ROW.match(lines[i - 1]):
            header = _cells(lines[i - 1])
            rows = []
            for line in lines[i + 1:]:
                if not ROW.match(line):
                    break
                rows.append(dict(zip(header, _cells(line))))
            tables.append((header, rows))
    return tables


def _cells(line):
    return [cell.strip() for cell in ROW.match(line).group(1).split("|")]


def number(cell):
    """The first number in a cell ('2.2x', '62%', '1.8e-06 / 1.1e-05', 'h = 0.1': its first)."""
    found = re.search(r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?", cell)
    if found is None:
        raise ValueError(f"no number in {cell!r}")
    return float(found.group(0))
