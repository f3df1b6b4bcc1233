"""Actions of the stiff extremes: m -> 0, gamma = 0, kappa = 1e4 and scale ratios 1e-6 .. 1e6.

Each ``action(variant, **params) -> Outcome`` of the table in ``benchmarks/extremes``.
"""

from dataclasses import replace

import numpy as np

from . import scenes as lib
from .scenes import Outcome


def _sim(*args, **kw):
    from polymatch_ros.core import simulate
    return simulate(*args, **kw)


# -- m = 1e-8 (Prop. 2.1 rates, first-order limit A-2) ----------------------------------------

def stiff_mass_refusals(v):
    from polymatch_ros.core import METHODS
    sc = lib.stiff_mass_scene(2, v.fields()["n_stiff"], t_end=2.0)
    lam = list(np.roots([1e-8, 2.0, 1.5])) + [-2.0 / 1e-8]
    parts, ok = [], True
    for dt in (0.01, 0.05):
        for name in lib.EXPLICIT:
            exc = lib.refusal(sc, name, dt)
            msg = str(exc) if exc else ""
            limit = lib.refusal_limit(exc)
            want = lib.rk_stability_limit(METHODS[name].info.order, lam)
            ok &= (exc is not None and exc.exit_code == 2 and "\n" not in msg and limit is not None
                   and abs(limit / want - 1) < 5e-3 and all(w in msg for w in (name, "m/gamma",
                                                                               "etd2")))
            if dt == 0.01:
                parts.append(f"{name} dt < {limit:.3g}" if limit else f"{name}: ran")
    return Outcome("all refuse (exit 2, one line): " + ", ".join(parts) + " (m/gamma = 5e-9)", ok)


def stiff_mass_verlet(v):
    scene = lib.stiff_mass_scene(2, v.fields()["n_stiff"], t_end=2.0)
    exc = lib.refusal(scene, "lie_verlet", 0.02)
    msg, limit = str(exc), lib.refusal_limit(exc)
    expected = 2.0 / np.sqrt(1.5 / 1e-8)
    ok = limit is not None and abs(limit / expected - 1) < 5e-3 and "etd2" in msg
    return Outcome(f"refuses: dt < {limit:.3g} = 2 sqrt(m/kappa); message blames 'damping stiff' "
                   "(it is exact)", ok)


def _stiff_reference(v):
    f = v.fields()
    samples = list(np.arange(0.0, f["t_stiff"] + 1.0, 1.0))          # on every step grid below
    first = lib.stiff_mass_scene(1, f["n_stiff"], t_end=f["t_stiff"], samples=samples)
    return first, _sim(first, "rkmk4", 1e-3), samples


def stiff_mass_etd2(v):
    first, ref, samples = _stiff_reference(v)
    rows, errs = [], []
    for dt in (0.04, 0.02) if v.quick else (0.04, 0.02, 0.01, 0.005):
        a = _sim(lib.stiff_mass_scene(2, len(first.initial.groups[0].x), t_end=first.t_end,
                                      samples=samples), "etd2", dt)
        err = max(lib.max_error(first, ref.final, a.scene, a.final),
                  max(abs(p.diameter - q.diameter) for p, q in zip(a.metrics, ref.metrics)))
        errs.append(err)
        rows.append((f"{dt:g}", f"{err:.2e}", f"{errs[-2] / err:.2f}" if len(errs) > 1 else "-",
                     f"{a.wall_time:.2f}", "yes" if lib.finite(a) else "NO"))
    ratios = [p / q for p, q in zip(errs, errs[1:])]
    return Outcome(f"runs; error vs (A-2) {errs[0]:.1e} at dt = 0.04 .. {errs[-1]:.1e} "
                   f"at dt = {rows[-1][0]}, ratio per halving "
                   f"{min(ratios):.2f}-{max(ratios):.2f} (O(dt^2))",
                   errs[0] < 1e-3 and all(3.0 < r < 5.0 for r in ratios), tuple(rows))


def stiff_mass_sweep(v):
    first, ref, samples = _stiff_reference(v)
    out, ok, prev = [], True, None
    for m in (1e-1, 1e-2, 1e-3, 1e-4):
        a = _sim(lib.stiff_mass_scene(2, len(first.initial.groups[0].x), mass=m, t_end=first.t_end,
                                      samples=samples), "etd2", 2.5e-3)
        err = lib.max_error(first, ref.final, a.scene, a.final)
        out.append(f"m = {m:g}: {err:.1e}")
        ok &= prev is None or 5 < prev / err < 20          # O(m/gamma)
        prev = err
    return Outcome("error vs (A-2) at dt = 2.5e-3: " + ", ".join(out) + " (O(m))", ok)


def stiff_mass_auto(v):
    from polymatch_ros.core import PolymatchError
    sc = lib.stiff_mass_scene(2, v.fields()["n_stiff"], t_end=1.0)
    sc = replace(sc, integrator=replace(sc.integrator, method="auto", tolerance=1e-6,
                                        max_steps=300 if v.quick else 3000))
    try:
        traj = _sim(sc, samples=[0.0], keep_states=False)
    except PolymatchError as exc:
        return Outcome(f"refused: '{exc}'", "\n" not in str(exc))
    return Outcome(f"auto picks {traj.numerics.name} and finishes ({traj.steps} steps)",
                   traj.numerics.name == "etd2" and abs(traj.final.t - 1.0) < 1e-12)


# -- gamma = 0 (Prop. 2.2 i) --------------------------------------------------------------------

def energy_deviation(method, t_end, dt=0.1):
    """Max relative energy deviation in the first tenth and in the last tenth of the run,
    E(t_end)/E0 - 1, and the trajectory (a tuple of the four)."""
    traj = _sim(lib.undamped_scene(t_end), method, dt)
    e = np.array([m.groups[0].energy for m in traj.metrics])
    dev = np.abs(e - e[0]) / e[0]
    k = len(dev) // 10
    return dev[:k].max(), dev[-k:].max(), (e[-1] - e[0]) / e[0], traj


def undamped_energy(v, method):
    early, late, final, traj = energy_deviation(method, v.fields()["t_undamped"])
    rows = ((method, f"{early:.2e}", f"{late:.2e}", f"{final:+.2e}", traj.steps,
             f"{traj.wall_time:.2f}"),)
    if method != "lie_verlet":
        return Outcome(
            f"energy drifts: {early:.1e} -> {late:.1e} (not symplectic; shown for contrast)",
            lib.finite(traj), rows)
    return Outcome(
        f"{traj.steps} steps: relative energy error <= {early:.1e} in the first tenth, {late:.1e} "
        "in the last (bounded oscillation, no drift)",
        late < 2.0 * early and max(early, late) < 2e-3 and lib.finite(traj), rows)


def undamped_refusals(v):
    parts, ok = [], True
    for name in ("lie_euler", "lie_heun", "euler_proj", "etd1"):
        exc = lib.refusal(lib.undamped_scene(10.0), name, 0.05)
        msg, limit = str(exc or ""), lib.refusal_limit(exc)
        ok &= all(w in msg for w in (name, "gamma = 0", "lie_verlet")) and "\n" not in msg
        parts.append(f"{name}: " + (f"'dt < {limit:.3g}'" if limit else "no stable step"))
    return Outcome("refused: " + ", ".join(parts), ok)


def undamped_no_stable_step(v):
    excs = [lib.refusal(lib.undamped_scene(10.0), m, 0.05) for m in ("lie_euler", "lie_heun")]
    msgs = [str(e or "") for e in excs]
    return Outcome(f"'{msgs[0]}'", all("no stable step" in m and not lib.refusal_limit(e)
                                       for m, e in zip(msgs, excs)))


# -- kappa = 1e4 --------------------------------------------------------------------------------

def stiff_coupling_refusals(v):
    from polymatch_ros.core import METHODS
    kappa, parts, ok = 1e4, [], True
    for order, dt in ((1, 0.01), (2, 0.05)):
        lam = [-kappa] if order == 1 else list(np.roots([1.0, 1.0, kappa])) + [-1.0]
        for name in lib.EXPLICIT:
            exc = lib.refusal(lib.stiff_coupling_scene(order, v.fields()["n_coupling"], 1.0),
                              name, dt)
            msg, limit = str(exc), lib.refusal_limit(exc)
            want = lib.rk_stability_limit(METHODS[name].info.order, lam)
            ok &= limit is not None and abs(limit / want - 1) < 5e-3 and "kappa" in msg
            if name == "rkmk4":
                parts.append(f"order {order}: rkmk4 dt < {limit:.3g}")
    return Outcome("all refuse; " + ", ".join(parts) + " (2.785/kappa; 2.83/sqrt(kappa/m))", ok)


def _coupling_reference(v):
    sc = lib.stiff_coupling_scene(1, v.fields()["n_coupling"], 5e-3, samples=[0.0, 1e-3, 5e-3])
    return sc, _sim(sc, "rkmk4", 2.5e-6)


def stiff_coupling_compliant(v):
    sc, ref = _coupling_reference(v)
    errs, rows = [], []
    for h in (1e-4, 5e-5, 2e-5) if v.quick else (1e-4, 5e-5, 2e-5, 1e-5):
        traj = _sim(sc, "rkmk4", h)
        errs.append(lib.max_error(sc, traj.final, sc, ref.final))
        rows.append(("rkmk4", f"h = {h:g} (h kappa = {h * 1e4:g})", traj.steps, traj.rhs_evals,
                     f"{errs[-1]:.1e}", f"{traj.wall_time:.2f}"))
    return Outcome(
        f"rkmk4 error {errs[0]:.1e} at h kappa = 1 .. {errs[-1]:.1e} at h kappa = 0.1 or 0.2",
        errs[2] < 1e-6, tuple(rows))


def stiff_coupling_adaptive(v):
    sc, ref = _coupling_reference(v)
    out, rows, ok = [], [], True
    for tol in (1e-6, 1e-8, 1e-10):
        traj = _sim(sc, "adaptive", tolerance=tol)
        err = lib.max_error(sc, traj.final, sc, ref.final)
        rows.append(("adaptive", f"tolerance {tol:g}", traj.steps, traj.rhs_evals, f"{err:.1e}",
                     f"{traj.wall_time:.2f}"))
        out.append(f"tol {tol:g}: {traj.steps} steps/{traj.rhs_evals} evals, error {err:.0e}")
        ok &= lib.finite(traj) and err < 100 * tol
    return Outcome("; ".join(out), ok, tuple(rows))


# -- scale ratios 1e-6 .. 1e6 (F-1) -------------------------------------------------------------

def f1_stiffness(sc):
    """Fastest rate of the F-1 linearisation at consensus.

    J = (kappa/N) D^{-1} (1 s^T - sum(s) I)."""
    s = np.asarray(sc.model.groups[0].scales)
    jac = (sc.model.kappa / len(s)) * (np.outer(1.0 / s, s) - np.diag(np.sum(s) / s))
    return float(np.max(np.abs(np.linalg.eigvals(jac))))


def scale_refusals(v):
    parts, ok = [], True
    for order in (1, 2):
        for name in ("lie_euler", "rkmk4", "rk4_proj") + (("etd2",
                                                           "lie_verlet") if order == 2 else ()):
            exc = lib.refusal(lib.scale_ratio_scene(order), name, 0.05)
            msg = str(exc or "")
            ok &= "scale ratios" in msg and "s_k/s_i" in msg
            if name == "rkmk4":
                parts.append(f"order {order}: rkmk4 dt < {lib.refusal_limit(exc):.3g}")
    s = lib.scale_ratio_scene(1).model.groups[0].scales
    return Outcome(
        f"all refuse naming 's_k/s_i' (s_max/s_min = {s.max() / s.min():.1e}, stiffness "
        f"{f1_stiffness(lib.scale_ratio_scene(1)):.2e}); " + ", ".join(parts), ok)


def scale_compliant(v):
    t_end = 2e-7 if v.quick else 2e-6
    sc = lib.scale_ratio_scene(1, t_end=t_end, samples=[0.0, t_end / 2, t_end])
    ref, run = _sim(sc, "rkmk4", 1.25e-10), _sim(sc, "rkmk4", 1e-9)
    err = lib.max_error(sc, run.final, sc, ref.final)
    return Outcome(
        f"rkmk4 h = 1e-9 (h k = {1e-9 * f1_stiffness(sc):.2f}): error {err:.1e} vs h/8 over "
        f"{run.steps} steps", err < 1e-9)


def scale_adaptive(v):
    from polymatch_ros.core import PolymatchError
    budget = v.fields()["budget"]
    try:
        _sim(lib.scale_ratio_scene(1, max_steps=budget), "adaptive", tolerance=1e-8,
             keep_states=False, samples=[0.0])
    except PolymatchError as exc:
        msg = str(exc)
        ok = ("\n" not in msg and "stiff" in msg and "s_k/s_i" in msg and exc.exit_code == 1
              and f"max_steps = {budget}" in msg)
        return Outcome(f"refuses before stepping: '{msg}'", ok)
    return Outcome("finished", True)
