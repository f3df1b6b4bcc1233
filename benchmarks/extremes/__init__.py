"""Stability at the extremes (`python -m benchmarks extremes`): one table, heavy variants.

Every extreme has a stated expectation: an accurate answer (against a reference),
a clear refusal (one line, an exception with an exit code, the cause and the
limit named) or a warning -- never NaN, never a silent wrong answer.  Each row
says what happened and whether the expectation held (the report's pass/fail column;
test/core/test_extremes.py states its own expectations and checks them on its own runs).

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
    explain_large  `polymatch explain` at N = 10^4, 10^5, 10^6: checks in O(N log N)

``--quick`` runs every extreme at toy sizes (seconds); ``--only a,b`` selects extremes.

The table of cases is here; ``scenes`` builds the scenes (the tests build theirs there too)
and measures runs, ``stiff`` and ``geometry`` hold the actions that run the cases.
"""

from dataclasses import dataclass

from . import scenes as lib
from .geometry import (
    coincident_asymmetry,
    coincident_at,
    coincident_pairs,
    collinear,
    d0_random,
    dim10,
    dt_gt_t_end,
    equilibrium,
    equilibrium_verdict,
    explain_large,
    explicit_at_1e9,
    huge_coords,
    large_n,
    long_horizon,
    one_agent,
)
from .scenes import Variant
from .stiff import (
    scale_adaptive,
    scale_compliant,
    scale_refusals,
    stiff_coupling_adaptive,
    stiff_coupling_compliant,
    stiff_coupling_refusals,
    stiff_mass_auto,
    stiff_mass_etd2,
    stiff_mass_refusals,
    stiff_mass_sweep,
    stiff_mass_verlet,
    undamped_energy,
    undamped_no_stable_step,
    undamped_refusals,
)

NAME = "extremes"
HELP = "stability at the extremes: expectation, what happened, pass/fail and wall time per extreme"

KEYS = ("stiff_mass", "undamped", "stiff_coupling", "large_n", "dim10", "long_horizon",
        "huge_coords",
        "scale_ratios", "equilibria", "d0_random", "coincident", "collinear", "dt_gt_t_end",
        "one_agent", "explain_large")

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
    "explain_large": ("`polymatch explain SCENE` as a process: load, plan, preflight, certificate",
                      ["N", "d", "rotations", "exit", "wall s", "certificate"]),
    "collinear": ("Nearly collinear triangles (length 1, height h), explicit vertices, "
                  "5 agents, first order",
                  ["d", "height", "outcome"]),
}


@dataclass(frozen=True)
class Case:
    """One stated expectation: ``action(variant, **params) -> Outcome``."""

    key: str
    label: str              # formatted with Variant.fields()
    expectation: str
    action: object
    params: tuple = ()      # (name, value) pairs
    quick: bool = True      # also in the quick variant (--quick)

    def run(self, variant):
        return self.action(variant, **dict(self.params))

    def title(self, variant):
        return self.label.format(**variant.fields())


C = Case
CASES = (
    C("stiff_mass", "m = 1e-8, dt = 0.01/0.05, explicit RK", "refuse: 'dt <' ~2..2.8 m/gamma",
      stiff_mass_refusals),
    C("stiff_mass", "m = 1e-8, lie_verlet", "refuse at 2 sqrt(m/kappa)", stiff_mass_verlet),
    C("stiff_mass", "m = 1e-8, etd2", "agrees with first order (A-2) to O(m/gamma) + O(dt^2)",
      stiff_mass_etd2),
    C("stiff_mass", "m -> 0 sweep, etd2", "error O(m/gamma) (first-order limit)", stiff_mass_sweep,
      quick=False),
    C("stiff_mass", "m = 1e-8 with a tolerance, integrator auto", "etd2, or a prompt refusal",
      stiff_mass_auto),
    C("undamped", "gamma = 0, lie_verlet, t_end = {t_undamped:g}",
      "energy (Prop. 2.2 i) without secular drift",
      undamped_energy, (("method", "lie_verlet"),)),
    C("undamped", "gamma = 0, rkmk4, t_end = {t_undamped:g}", "runs (stable), drifts: contrast",
      undamped_energy, (("method", "rkmk4"),), quick=False),
    C("undamped", "gamma = 0, etd2, t_end = {t_undamped:g}", "runs (stable), drifts: contrast",
      undamped_energy, (("method", "etd2"),)),
    C("undamped", "gamma = 0, lie_euler/lie_heun/euler_proj/etd1",
      "refuse, naming gamma = 0 (one line)",
      undamped_refusals),
    C("undamped", "gamma = 0, methods with no stable step", "say 'no stable step'",
      undamped_no_stable_step),
    C("stiff_coupling", "kappa = 1e4, explicit fixed step", "refuse beyond ~2.8/kappa",
      stiff_coupling_refusals),
    C("stiff_coupling", "kappa = 1e4, rkmk4 at compliant h", "accurate vs reference (h = 2.5e-6)",
      stiff_coupling_compliant),
    C("stiff_coupling", "kappa = 1e4, adaptive",
      "accurate; cost ~ t_end kappa / stability boundary",
      stiff_coupling_adaptive),
    C("large_n", "N = {n_large}, order 1, rkmk4 dt = 0.1",
      "full run converges; metrics finite and exact",
      large_n, (("order", 1),)),
    C("large_n", "N = {n_large}, order 2, rkmk4 dt = 0.1",
      "full run converges; metrics finite and exact",
      large_n, (("order", 2),), quick=False),
    *(C("dim10", f"d = 10, N = {{n_dim10}}, order {o}", "stays in SO(10) to 1e-12; converges",
        dim10,
        (("order", o),)) for o in (1, 2)),
    *(C("long_horizon", f"t_end = {{t_long:g}}, d = {d}, order {o}, {m}",
        "no orthogonality drift; converged stays converged", long_horizon,
        (("dim", d), ("order", o), ("method", m), ("h", h)), quick=q)
      for d, o, m, h, q in ((3, 1, "rkmk4", 2.5, True), (4, 1, "rkmk4", 2.5, False),
                            (3, 2, "lie_verlet", 0.5, False), (3, 2, "etd2", 0.5, False),
                            (3, 1, "adaptive", 1e-8, True), (3, 2, "adaptive", 1e-8, False))),
    *(C("huge_coords", f"centroids ~1e9, d = {d}, order {o}{', mixed F-2' if mixed else ''}",
        "diameters = translated scene's to 1e-12 of the shape", huge_coords,
        (("dim", d), ("order", o), ("mixed", mixed)), quick=q)
      for d, o, mixed, q in ((2, 1, False, True), (3, 2, False, False), (3, 2, True, True))),
    C("huge_coords", "explicit vertices at 1e9", "load (within input precision 1e-7)",
      explicit_at_1e9),
    C("scale_ratios", "scales 1e-6 .. 1e6 (F-1), explicit fixed step",
      "refuse naming the scale ratios",
      scale_refusals),
    C("scale_ratios", "scales 1e-6 .. 1e6, compliant dt", "accurate vs reference",
      scale_compliant),
    C("scale_ratios", "scales 1e-6 .. 1e6, adaptive (max_steps {budget})",
      "a prompt one-line PolymatchError naming the stiffness", scale_adaptive),
    *(C("equilibria", f"{lib.EQUILIBRIA[name][0]}, order {o}, {rep}",
        "reproduced; only round-off growth of the unstable mode", equilibrium,
        (("name", name), ("order", o), ("rep", rep)), quick=(name, o, rep) == ("antipodal_2d", 1,
                                                                               "auto"))
      for name in lib.EQUILIBRIA for o in (1, 2) for rep in ("auto", "matrix")),
    C("equilibria", "antipodal SO(2), CLI verdict at t_end = 10",
      "exit 3 naming the non-consensus equilibrium",
      equilibrium_verdict),
    *(C("d0_random", f"D0 >= 1, uniform random, N = 8, d = {d}", "converges (outside Thm 4.2)",
        d0_random,
        (("dim", d),)) for d in (2, 3)),
    *(C("coincident", f"coincident centroids (F-2), order {o}, at {at[0]:g}",
        "finite; stay together",
        coincident_at, (("order", o), ("at", at)), quick=o == 2)
      for o in (1, 2) for at in ((0.0, 0.0), (1e9, 1e9))),
    C("coincident", "coincident centroids + asymmetry 1e-15 .. 1e-6", "groups separate to L",
      coincident_asymmetry),
    C("coincident", "coincident pairs across groups, translated copy",
      "finite; separate to L; path decided by round-off", coincident_pairs),
    *(C("collinear", f"nearly collinear triangle, d = {d}, heights 1e-3 .. 0",
        "decomposes; converges", collinear,
        (("dim", d),)) for d in (2, 3)),
    *(C("dt_gt_t_end", f"dt = 5 > t_end = 0.3, order {o}", "warning; one step of t_end; finite",
        dt_gt_t_end,
        (("order", o),)) for o in (1, 2)),
    *(C("one_agent", f"one agent, order {o}", "trivially converged, no crash", one_agent,
        (("order", o),))
      for o in (1, 2)),
    C("explain_large", "explain, N = 10^4, 10^5, 10^6, d = 2 and 3",
      "at most 5 s at N = 10^6 (uniform rotations)", explain_large),
)


def add_arguments(p):
    from ..options import at_least
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

    from ..report import Report
    keys = list(KEYS)
    if getattr(args, "only", None):
        wanted = [k.strip() for k in args.only.split(",") if k.strip()]
        unknown = [k for k in wanted if k not in KEYS]
        if unknown:
            from polymatch_ros.core import ParameterError
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
    report = Report(NAME, "Stability at the extremes (`python -m benchmarks extremes`)")
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
