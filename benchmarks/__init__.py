"""`python -m benchmarks FAMILY [options]`: benchmarks that report the core's figures.

    python -m benchmarks step         one integrator step (rkmk4 at N = 10,000, d = 3, ...)
    python -m benchmarks meanfield    mean field S = sum_k O_k against the naive O(N^2) sum
    python -m benchmarks dop853       adaptive Lie DOP853 against scipy's DOP853 at a target error
    python -m benchmarks precision    work-precision: every integrator and scipy, error vs cost
    python -m benchmarks longhorizon  orthogonality defect and energy drift after 10^5 steps
    python -m benchmarks packing      lockstep rounds/s of `polymatch run`: N agents in P processes
    python -m benchmarks scaling      lockstep at 8 ... 4096 agents: rounds/s, start-up, memory
    python -m benchmarks lossy        three namespace hosts: realtime error, lockstep rate vs loss
    python -m benchmarks bridge       simulated robots in the loop: error vs pose noise and lag
    python -m benchmarks realtime_scale  realtime, 8 ... 1024 agents at 10 ... 50 Hz: late ticks
    python -m benchmarks watching     lockstep rounds/s with the monitor over without, 8 ... 1024
    python -m benchmarks faults       process deaths: a realtime soak with kills, lockstep resumes
    python -m benchmarks leftovers    /dev/shm after a run; rounds/s with and without its clean-up
    python -m benchmarks process_start  a run's CPU: node processes forked (runner's fork, fresh
                                        server) or exec'd
    python -m benchmarks basins       basins of consensus on rings and random graphs, d = 2, 3, 4
    python -m benchmarks all --out DIR [--only A,B]   every family, one report DIR/report.md

Benchmarks *report* figures (markdown tables on stdout; with ``--out DIR``
also ``DIR/<family>.md`` and PNG plots); they are not tests and assert nothing
about timing.  They live beside the package, in a checkout, and run from its root.

Adding a family: write a module here that defines

    NAME = "scaling"                 # the family's name on the command line
    HELP = "one line for --help"
    def add_arguments(parser): ...   # its own options (--out, --quick, --repeats, --quiet: common)
    def run(args, log) -> Report     # log(text) prints progress to stderr

and add it to ``FAMILIES`` below, at its place in the report.  ``run`` must honour
``args.quick`` (tiny sizes, a few seconds: the smoke test runs every family so) and import
heavy modules (the core, scipy) inside ``run``, not at module level, so that
``python -m benchmarks --help`` stays fast.
"""

import argparse
import importlib
import os
import sys
import time
import traceback

from polymatch_ros import cli
from polymatch_ros.core.errors import ParameterError

from .report import Report
from .timing import machine_lines

PROG = "python -m benchmarks"

#: family name -> module, in report order (``all`` runs them in this order); a module that
#: fails to import is an error, never a family silently missing
FAMILIES = {
    "step": "benchmarks.core_families.step",
    "meanfield": "benchmarks.core_families.meanfield",
    "dop853": "benchmarks.core_families.dop853",
    "precision": "benchmarks.core_families.precision",
    "extremes": "benchmarks.extremes",
    "longhorizon": "benchmarks.core_families.longhorizon",
    "distributed": "benchmarks.ros_families.distributed",
    "packing": "benchmarks.ros_families.packing",
    "scaling": "benchmarks.ros_families.scaling",
    "sweep": "benchmarks.core_families.sweep",
    "basins": "benchmarks.core_families.basins",
    "graphs": "benchmarks.ros_families.graphs",
    "lossy": "benchmarks.ros_families.lossy",
    "trade": "benchmarks.ros_families.trade",
    "bridge": "benchmarks.ros_families.bridge",
    "realtime": "benchmarks.ros_families.realtime",
    "realtime_scale": "benchmarks.ros_families.realtime_scale",
    "watching": "benchmarks.ros_families.watching",
    "reductions": "benchmarks.core_families.reductions",
    "faults": "benchmarks.ros_families.faults",
    "leftovers": "benchmarks.process_families.leftovers",
    "process_start": "benchmarks.process_families.process_start",
}


class Parser(cli.Parser):
    """The ``polymatch`` parser (one-line errors, exit code 2), errors prefixed ``benchmarks:``."""

    def error(self, message):
        hint = f"see `{self.prog} --help`"
        self.exit(2, f"benchmarks: error: {message.splitlines()[0]} ({hint})\n")


def families():
    """The family modules, in report order (``FAMILIES``)."""
    modules = []
    for name, module_name in FAMILIES.items():
        module = importlib.import_module(module_name)
        if module.NAME != name:
            raise ImportError(f"{module_name} defines NAME = {module.NAME!r}, not {name!r}")
        modules.append(module)
    return modules


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


def build_parser():
    """The parser of ``python -m benchmarks``: one subcommand per family, plus ``all``."""
    paragraphs = __doc__.split("\n\n")
    parser = Parser(prog=PROG, description=paragraphs[0] + "\n\n" + paragraphs[1],
                    formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="family", metavar="FAMILY")
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
    return parser


def main(argv=None):
    """Run ``python -m benchmarks ARGS``; returns the exit code (2: bad input, 1: a failure)."""
    args = build_parser().parse_args(sys.argv[1:] if argv is None else list(argv))
    return cli.run_reporting_errors("benchmarks", lambda: args.func(args))



def _logger(quiet):
    def log(text):
        if not quiet:
            print(f"benchmarks: {text}", file=sys.stderr, flush=True)
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


def _selected(args, names):
    """The families ``--only`` names (all of them without it), in report order."""
    if not args.only:
        return names
    wanted = [n.strip() for n in args.only.split(",") if n.strip()]
    unknown = [n for n in wanted if n not in names]
    if unknown:
        raise ParameterError(f"unknown benchmark family {unknown[0]!r}; known: {', '.join(names)}")
    return [n for n in names if n in wanted]


def cmd_all(args):
    parsers = args.bench_parsers
    names = _selected(args, list(parsers))
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
    if text.startswith("# "):           # written by `python -m benchmarks NAME --out`: one level
        lines = ("#" + line if line.startswith("#") else line for line in text.splitlines())
        text = "\n".join(lines) + "\n"
    return text
