"""`polymatch bench <family> [options]`: benchmarks that report the core's figures.

    polymatch bench step         wall time of one integrator step (rkmk4 at N = 10,000, d = 3, ...)
    polymatch bench meanfield    mean field S = sum_k O_k against the naive O(N^2) double sum
    polymatch bench dop853       adaptive Lie DOP853 against scipy's DOP853 at a target error
    polymatch bench precision    work-precision: every integrator and scipy, run error vs cost
    polymatch bench longhorizon  orthogonality defect and energy drift (gamma = 0) after 10^5 steps
    polymatch bench lossy        three namespace hosts: realtime error and lockstep rate vs loss
    polymatch bench bridge       simulated robots in the loop: matching error vs pose noise and lag
    polymatch bench all --out DIR   every family, one report DIR/report.md

Benchmarks *report* figures (markdown tables on stdout; with ``--out DIR``
also ``DIR/<family>.md`` and PNG plots); they are not tests and assert nothing
about timing.

Adding a family: add a module to this package that defines

    NAME = "scaling"                 # the sub-subcommand
    HELP = "one line for --help"
    ORDER = 40                       # position in `bench all` (default 100)
    def add_arguments(parser): ...   # its own options (--out, --quick, --repeats, --quiet: common)
    def run(args, log) -> Report     # log(text) prints progress to stderr

Modules are discovered, so nothing else needs editing.  ``run`` must honour
``args.quick`` (tiny sizes, a few seconds: the smoke test runs every family so)
and import heavy modules (the core, scipy) inside ``run``, not at module level,
so that ``polymatch --help`` stays fast.
"""

import argparse
import importlib
import os
import pkgutil
import sys
import time
import traceback

from .report import Report
from .timing import machine_lines

#: modules of this package that are helpers, not families
HELPERS = frozenset({"report", "timing", "scenes", "options", "flat", "solve", "extremes_lib",
                      "extremes_cases", "extremes_stiff", "extremes_geometry", "netns",
                      "netns_run", "lossy_tables", "precision_tables", "ros_runs",
                      "dop853_tables"})


def families():
    """Family modules, in report order."""
    mods = []
    for info in pkgutil.iter_modules(__path__):
        if info.name.startswith("_") or info.name in HELPERS:
            continue
        try:
            mod = importlib.import_module(f"{__name__}.{info.name}")
        except Exception as exc:   # a broken family must not take `polymatch` down with it
            print(f"polymatch: warning: benchmark family {info.name!r} not loaded: {exc}",
                  file=sys.stderr)
            continue
        if hasattr(mod, "NAME") and hasattr(mod, "run"):
            mods.append(mod)
    return sorted(mods, key=lambda m: (getattr(m, "ORDER", 100), m.NAME))


def add_common_options(p):
    p.add_argument("--out", metavar="DIR", help="also write DIR/<family>.md and PNG plots")
    p.add_argument("--quick", action="store_true",
                   help="tiny sizes, a few seconds (smoke test; the figures mean nothing)")
    p.add_argument("--repeats", type=_positive_int, metavar="R",
                   help="timing repeats (default: the family's)")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress on stderr")


def _positive_int(text):
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {value}")
    return value


def add_parser(subparsers):
    """Register `polymatch bench` and one sub-subcommand per family, plus `all`."""
    paragraphs = __doc__.split("\n\n")
    p = subparsers.add_parser("bench", help="benchmarks: speed and accuracy figures "
                              "(see `polymatch bench -h`)",
                              description=paragraphs[0] + "\n\n" + paragraphs[1],
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="family", metavar="FAMILY")
    sub.required = True
    parsers = {}
    for mod in families():
        fp = sub.add_parser(mod.NAME, help=mod.HELP, description=(mod.__doc__ or mod.HELP).strip(),
                            formatter_class=argparse.RawDescriptionHelpFormatter)
        mod.add_arguments(fp)
        add_common_options(fp)
        fp.set_defaults(func=cmd_family, bench_module=mod)
        parsers[mod.NAME] = fp
    ap = sub.add_parser("all", help="run every family and write one report DIR/report.md")
    ap.add_argument("--out", metavar="DIR", required=True, help="output directory")
    ap.add_argument("--only", metavar="A,B", help="only these families (comma separated); "
                    "report.md keeps the other families' last reports found in DIR")
    ap.add_argument("--quick", action="store_true", help="tiny sizes for every family")
    ap.add_argument("--repeats", type=_positive_int, metavar="R",
                    help="timing repeats for every family")
    ap.add_argument("--quiet", "-q", action="store_true", help="no progress on stderr")
    ap.set_defaults(func=cmd_all, bench_parsers=parsers)
    return p


def _logger(quiet):
    def log(text):
        if not quiet:
            print(f"[bench] {text}", file=sys.stderr, flush=True)
    return log


def _run_family(mod, args):
    log = _logger(args.quiet)
    t0 = time.perf_counter()
    report = mod.run(args, log)
    elapsed = time.perf_counter() - t0
    try:
        load = "load average {:.2f} {:.2f} {:.2f}".format(*os.getloadavg())
    except OSError:
        load = "load average unknown"
    report.text(f"_{mod.NAME}: {elapsed:.1f} s in all; {load} at the end "
                f"(other processes on this machine inflate and scatter the timings)._")
    log(f"{mod.NAME}: done in {elapsed:.1f} s")
    return report


def cmd_family(args):
    machine = machine_lines()
    report = _run_family(args.bench_module, args)
    report.blocks.insert(0, ("text", "\n".join(f"- {line}" for line in machine)))
    if args.out:
        text = report.write(args.out, level=1)
        print(text, end="")
        print(f"written: {os.path.join(args.out, report.family + '.md')}"
              f"{' and ' + str(len(report.figures)) + ' PNG figure(s)' if report.figures else ''}",
              file=sys.stderr)
    else:
        print(report.markdown(level=1), end="")
    return 0


def cmd_all(args):
    parsers = args.bench_parsers
    names = list(parsers)
    if args.only:
        wanted = [n.strip() for n in args.only.split(",") if n.strip()]
        unknown = [n for n in wanted if n not in parsers]
        if unknown:
            print(f"polymatch: error: unknown benchmark family {unknown[0]!r}; "
                  f"known: {', '.join(names)}", file=sys.stderr)
            return 2
        names = [n for n in names if n in wanted]
    extra = ((["--quick"] if args.quick else [])
             + (["--repeats", str(args.repeats)] if args.repeats else [])
             + (["--quiet"] if args.quiet else []))
    os.makedirs(args.out, exist_ok=True)
    sections, failed = [], []
    machine = machine_lines()
    for name in names:
        fargs = parsers[name].parse_args(extra)
        fargs.out = args.out
        try:
            report = _run_family(fargs.bench_module, fargs)
        except Exception:   # one broken family must not lose the others' figures
            failed.append(name)
            tb = traceback.format_exc()
            print(tb, file=sys.stderr)
            report = Report(name, f"{name}: FAILED")
            report.text("```", tb.rstrip(), "```")
        sections.append((name, report.write(args.out, level=2)))
    head = ["# polymatch benchmark report", ""] + [f"- {line}" for line in machine] + [""]
    if args.quick:
        head += ["**--quick: tiny sizes; these figures only show that the benchmarks run.**", ""]
    if args.only:       # keep the other families' last reports: report.md stays whole
        fresh = dict(sections)
        sections = [(n, fresh[n] if n in fresh else _previous_section(args.out, n))
                     for n in parsers]
        sections = [(n, text) for n, text in sections if text is not None]
    head += ["Families: " + ", ".join(f"[{n}]({n}.md)" for n, _ in sections), ""]
    text = "\n".join(head) + "\n" + "\n".join(s for _, s in sections)
    path = os.path.join(args.out, "report.md")
    with open(path, "w", encoding="utf-8") as fh:
        fh.write(text)
    print(text, end="")
    print(f"written: {path}", file=sys.stderr)
    return 1 if failed else 0


def _previous_section(out_dir, name):
    """A family's report from an earlier run in ``out_dir``, as a level-2 section (or None)."""
    path = os.path.join(out_dir, f"{name}.md")
    if not os.path.isfile(path):
        return None
    with open(path, encoding="utf-8") as fh:
        text = fh.read()
    if text.startswith("# "):           # written by `polymatch bench NAME --out`: one level up
        lines = ("#" + line if line.startswith("#") else line for line in text.splitlines())
        text = "\n".join(lines) + "\n"
    return text
