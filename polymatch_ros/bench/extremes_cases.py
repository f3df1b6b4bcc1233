"""The extremes as one table: (extreme, label, expectation, action) rows.

Every row states an expectation -- an accurate answer, a clear refusal (one line, an
exception with an exit code, the cause and the limit named) or a warning, never NaN and
never a silent wrong answer -- and an action that runs the extreme at a ``Variant``'s sizes
and returns an ``Outcome`` (what happened, whether the expectation held, detail rows).
``polymatch bench extremes`` renders the full variants; ``test/test_extremes.py`` runs the
quick ones (rows with ``quick=True``) and asserts that each expectation holds.
"""

from dataclasses import dataclass

from . import extremes_lib as lib
from .extremes_geometry import (
    coincident_asymmetry,
    coincident_at,
    coincident_pairs,
    collinear,
    d0_random,
    dim10,
    dt_gt_t_end,
    equilibrium,
    equilibrium_verdict,
    explicit_at_1e9,
    huge_coords,
    large_n,
    long_horizon,
    one_agent,
)
from .extremes_stiff import (
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


@dataclass(frozen=True)
class Case:
    """One stated expectation: ``action(variant, **params) -> Outcome``."""

    key: str
    label: str              # formatted with Variant.fields()
    expectation: str
    action: object
    params: tuple = ()      # (name, value) pairs
    quick: bool = True      # also in the quick variant (tests, --quick)

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
)
