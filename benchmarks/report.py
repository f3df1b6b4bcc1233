"""What a benchmark family returns: text, markdown tables and (optional) PNG figures.

A ``Report`` is rendered as markdown to stdout; with ``--out DIR`` it is also
written to ``DIR/<family>.md`` with its figures as ``DIR/<family>_<name>.png``.
Figures are drawing callbacks, so nothing imports matplotlib unless a figure
is actually written.
"""

import os
import sys


def markdown_table(header, rows):
    """A pipe table, padded so it also reads well as plain text."""
    cells = [[str(c) for c in header]] + [[str(c) for c in r] for r in rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(header))]

    def line(r):
        return "| " + " | ".join(c.ljust(w) for c, w in zip(r, widths)) + " |"

    out = [line(cells[0]), "|" + "|".join("-" * (w + 2) for w in widths) + "|"]
    out += [line(r) for r in cells[1:]]
    return "\n".join(out)


class Report:
    """Ordered blocks of a family's output."""

    def __init__(self, family, title):
        self.family, self.title = family, title
        # ("text", str) | ("table", caption, header, rows) | ("figure", name)
        self.blocks = []
        self.figures = {}       # name -> (draw(plt) -> figure, caption)

    def text(self, *lines):
        self.blocks.append(("text", "\n".join(lines)))

    def failures(self, failures):
        """A 'Failed runs:' list, if there were any: a family reports, never hides, them."""
        if failures:
            self.text("Failed runs:", *[f"- {f}" for f in failures])

    def table(self, header, rows, caption=None):
        self.blocks.append(("table", caption, list(header), [list(r) for r in rows]))

    def figure(self, name, draw, caption):
        self.figures[name] = (draw, caption)
        self.blocks.append(("figure", name))

    def figure_file(self, name):
        return f"{self.family}_{name}.png"

    def markdown(self, written=(), level=2):
        """Markdown text; figures appear as images only if their file was ``written``."""
        out = [f"{'#' * level} {self.title}", ""]
        for block in self.blocks:
            if block[0] == "text":
                out += [block[1], ""]
            elif block[0] == "table":
                _, caption, header, rows = block
                if caption:
                    out += [f"**{caption}**", ""]
                out += [markdown_table(header, rows), ""]
            elif block[1] in written:
                out += [f"![{self.figures[block[1]][1]}]({self.figure_file(block[1])})", ""]
        return "\n".join(out).rstrip() + "\n"

    def write_figures(self, out_dir):
        """Render every figure to ``out_dir``; return the names written (none without
        matplotlib)."""
        if not self.figures:
            return []
        try:
            import matplotlib
            matplotlib.use("Agg")
            import matplotlib.pyplot as plt
        except ImportError:
            print("benchmarks: warning: matplotlib is not installed; no PNG figures "
                  "(pip install 'polymatch_ros[plot]')", file=sys.stderr)
            return []
        written = []
        for name, (draw, _caption) in self.figures.items():
            fig = draw(plt)
            fig.savefig(os.path.join(out_dir, self.figure_file(name)),
                        dpi=120, bbox_inches="tight")
            plt.close(fig)
            written.append(name)
        return written

    def write(self, out_dir, level=2):
        """Write ``<family>.md`` and the PNGs into ``out_dir``; returns the markdown text."""
        os.makedirs(out_dir, exist_ok=True)
        written = self.write_figures(out_dir)
        text = self.markdown(written, level)
        with open(os.path.join(out_dir, f"{self.family}.md"), "w", encoding="utf-8") as fh:
            fh.write(text)
        return text
