"""Stability at the extremes: heavy variants of test/test_extremes.py, one table.

Every extreme has a stated expectation: an accurate answer (against a reference),
a clear refusal (one line, an exception with an exit code, the cause and the
limit named) or a warning -- never NaN, never a silent wrong answer.  Each row
says what happened and whether the expectation held.

    stiff_mass     m = 1e-8 at dt = 0.01 .. 0.05: explicit refusals; etd2 vs the first-order model
    undamped       gamma = 0: lie_verlet energy over t = 10^4; refusals of the unstable methods
    stiff_coupling kappa = 1e4: refusals, rkmk4 at compliant dt, the adaptive method's cost
    large_n        N = 10^4: a full run to consensus (first and second order)
    dim10          d = 10: 100 simplices in SO(10)
    long_horizon   t_end = 10^4: orthogonality drift, converged stays converged (fixed, adaptive)
    huge_coords    centroids around 1e9 vs the same scene at the origin (N = 1000, mixed F-2)
    scale_ratios   similar ensemble with scales 1e-6 .. 1e6 (F-1)
    equilibria     antipodal (SO(2), SO(3)) and splay states: growth rate and escape time
    d0_random      D0 >= 1 with uniform random rotations, N = 8, 50 seeds
    coincident     all centroids of a mixed ensemble at one point
    collinear      nearly collinear triangles in R^2 and R^3
    dt_gt_t_end    dt larger than t_end
    one_agent      a single agent, every integrator

``--quick`` runs every extreme at toy sizes (seconds); ``--only a,b`` selects extremes.
"""

NAME = "extremes"
HELP = "stability at the extremes: expectation, what happened, pass/fail and wall time per extreme"
ORDER = 50

KEYS = ("stiff_mass", "undamped", "stiff_coupling", "large_n", "dim10", "long_horizon",
        "huge_coords",
        "scale_ratios", "equilibria", "d0_random", "coincident", "collinear", "dt_gt_t_end",
        "one_agent")

#: the detail table of an extreme: (caption, formatted with Variant.fields(), header)
DETAILS = {
    "stiff_mass": ("m = 1e-8: etd2 against the first-order model (A-2), N = {n_stiff}, "
                   "t_end = {t_stiff:g} (reference rkmk4 dt = 1e-3 on the first-order scene)",
                   ["dt", "max error (state, diameters)", "ratio", "wall s", "finite"]),
    "undamped": ("gamma = 0: relative energy deviation, N = 5, d = 2, dt = 0.1, "
                 "t_end = {t_undamped:g}",
                 ["method", "max, first tenth", "max, last tenth", "E(t_end)/E0 - 1", "steps",
                  "wall s"]),
    "stiff_coupling": ("kappa = 1e4, first order, N = {n_coupling}, t_end = 0.005 "
                       "(50 time constants 1/kappa): cost and error against rkmk4 h = 2.5e-6",
                       ["method", "setting", "steps", "evaluations", "max error", "wall s"]),
    "large_n": ("N = {n_large}, d = 3 (regular tetrahedra), rkmk4 dt = 0.1",
                ["order", "N", "steps", "D(0)", "D(t_end)", "converged at", "max orth. defect",
                 "wall s"]),
    "long_horizon": ("long horizon t_end = {t_long:g}, N = 6, matrix representation",
                     ["d", "order", "method", "setting", "steps", "orth. defect (first sample)",
                      "orth. defect (t_end)", "converged at", "max D after t = 100", "wall s"]),
    "equilibria": ("Non-consensus equilibria: deviation eps(t) from the equilibrium, "
                   "fitted eps0 e^{{rate t}} for 1e-11 < eps < 1e-3 "
                   "(rkmk4, dt = 0.05, kappa = gamma = 1, m = 0.5)",
                   ["equilibrium", "order", "representation", "eps(0)", "linear rate",
                    "measured rate",
                    "fitted eps0", "escape (eps > 0.5) at t", "predicted ln(0.5/eps0)/rate",
                    "converged by t_end"]),
    "coincident": ("Coincident centroids: one centroid moved by eps "
                   "(second order, kappa_2 = 0.5, L = 3)",
                   ["eps", "separation at t = 0", "separation > 1 at t", "separation at t_end",
                    "t_end"]),
    "collinear": ("Nearly collinear triangles (length 1, height h), explicit vertices, "
                  "5 agents, first order",
                  ["d", "height", "outcome"]),
}


def add_arguments(p):
    from .options import at_least
    p.add_argument("--only", metavar="A,B", help="only these extremes: " + ", ".join(KEYS))
    p.add_argument("--n-large", type=at_least(2), default=10_000,
                   help="N of the large-N run (default 10000)")
    p.add_argument("--t-long", type=at_least(1.0, float), default=1e4,
                   help="t_end of the long-horizon runs (default 1e4)")


def check(case, variant, log):
    """[extreme, expectation, what happened, pass/fail, wall s] and the detail rows of one case."""
    import time
    t0 = time.perf_counter()
    try:
        out = case.run(variant)
        happened, ok, rows = out.happened, out.ok, list(out.rows)
    except Exception as exc:           # a traceback where a one-line error was due is a finding
        first = str(exc).splitlines()[0] if str(exc) else ""
        happened, ok, rows = f"unexpected {type(exc).__name__}: {first}", False, []
    wall = time.perf_counter() - t0
    verdict = "pass" if ok else "FAIL"
    log(f"extremes: {case.key}: {verdict} ({wall:.1f} s)")
    return [case.title(variant), case.expectation, happened, verdict, f"{wall:.2f}"], rows


def run(args, log):
    import time

    from .extremes_cases import CASES
    from .extremes_lib import Variant
    from .report import Report
    keys = list(KEYS)
    if getattr(args, "only", None):
        wanted = [k.strip() for k in args.only.split(",") if k.strip()]
        unknown = [k for k in wanted if k not in KEYS]
        if unknown:
            from ..core import ParameterError
            raise ParameterError(
                f"--only: unknown extreme {unknown[0]!r}; known: {', '.join(KEYS)}")
        keys = [k for k in keys if k in wanted]
    variant = Variant(quick=args.quick, n_large=args.n_large, t_long=args.t_long)
    t0 = time.perf_counter()
    results, details = [], {}
    for key in keys:
        log(f"extremes: {key}")
        for case in CASES:
            if case.key == key and (case.quick or not args.quick):
                row, rows = check(case, variant, log)
                results.append(row)
                details.setdefault(key, []).extend(rows)
    report = Report(NAME, "Stability at the extremes (`polymatch bench extremes`)")
    passed = sum(r[3] == "pass" for r in results)
    report.text(f"{len(results)} expectations over {len(keys)} extremes: {passed} pass, "
                f"{len(results) - passed} fail; {time.perf_counter() - t0:.1f} s."
                + (" **--quick: toy sizes.**" if args.quick else ""))
    report.table(["extreme", "expectation", "what happened", "pass/fail", "wall s"], results,
                 caption="Extremes: expectation and outcome")
    for key in keys:
        if key in DETAILS:
            caption, header = DETAILS[key]
            report.table(header, details.get(key, []), caption=caption.format(**variant.fields()))
    return report
