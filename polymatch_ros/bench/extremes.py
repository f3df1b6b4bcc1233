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
    long_horizon   t_end = 10^4: orthogonality drift, converged stays converged (fixed and adaptive)
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

KEYS = ("stiff_mass", "undamped", "stiff_coupling", "large_n", "dim10", "long_horizon", "huge_coords",
        "scale_ratios", "equilibria", "d0_random", "coincident", "collinear", "dt_gt_t_end", "one_agent")


def add_arguments(p):
    from .options import at_least
    p.add_argument("--only", metavar="A,B", help="only these extremes: " + ", ".join(KEYS))
    p.add_argument("--n-large", type=at_least(2), default=10_000, help="N of the large-N run (default 10000)")
    p.add_argument("--t-long", type=at_least(1.0, float), default=1e4,
                   help="t_end of the long-horizon runs (default 1e4)")


# ---------------------------------------------------------------------------------------------
# plumbing


class Ctx:
    """Collects result rows and detail tables; ``check`` times one expectation."""

    def __init__(self, quick, log, args):
        self.quick, self.log, self.args = quick, log, args
        self.rows = []
        self.details = []         # (caption, header, rows)
        self.notes = []

    def check(self, extreme, expectation, fn):
        """fn() -> (what happened, ok).  Exceptions are results too (a crash is a FAIL)."""
        import time
        t0 = time.perf_counter()
        try:
            happened, ok = fn()
        except Exception as exc:              # a traceback where a one-line error was due is a finding
            happened, ok = f"unexpected {type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}", False
        wall = time.perf_counter() - t0
        verdict = "pass" if ok else "FAIL"
        self.rows.append([extreme, expectation, happened, verdict, f"{wall:.2f}"])
        self.log(f"extremes: {extreme}: {verdict} ({wall:.1f} s)")
        return ok

    def detail(self, caption, header, rows):
        self.details.append((caption, header, rows))


def _scene(dim, order=1, *, count=6, seed=1, kappa=1.0, gamma=1.0, mass=0.5, shape=None, rotations="uniform",
           centroids=None, velocities=None, t_end=10.0, samples=None, scales=None, representation="auto",
           max_steps=None):
    from ..core import load_scene
    model = {"order": order, "kappa": kappa, "gamma": gamma, "representation": representation}
    if order == 2:
        model["mass"] = mass
    group = {"name": "g", "shape": shape or {"simplex": dim}, "count": count, "rotations": rotations,
             "centroids": centroids or {"box": [-2.0, 2.0]}}
    if scales is not None:
        group["scales"] = scales
    if order == 2 and velocities is not None:
        group["velocities"] = velocities
    time = {"t_end": t_end}
    if samples is not None:
        time["samples"] = samples
    data = {"dimension": dim, "seed": seed, "model": model, "time": time, "groups": [group]}
    if max_steps is not None:
        data["integrator"] = {"max_steps": max_steps}
    return load_scene(data)


def _refusal(scene, method, dt):
    """(one-line message or None, limit named or None)."""
    from ..core import StabilityError, simulate
    try:
        simulate(scene, method, dt, keep_states=False, metrics=False, samples=[0.0])
    except StabilityError as exc:
        return str(exc), (exc.limit if exc.limit else None)
    return None, None


def _rk_limit(order, eigenvalues):
    """Largest h with |R(h lambda)| <= 1 for the explicit RK stability polynomial of this order."""
    coefs = {1: [1, 1], 2: [1, 1, 0.5], 4: [1, 1, 0.5, 1 / 6, 1 / 24]}[order]

    def ok(h):
        return all(abs(sum(c * (h * lam) ** k for k, c in enumerate(coefs))) <= 1.0 for lam in eigenvalues)

    lo, hi = 0.0, 100.0 / max(abs(lam) for lam in eigenvalues)
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if ok(mid) else (lo, mid)
    return lo


def _finite(traj):
    import numpy as np
    states = list(traj.states) + [traj.final]
    for st in states:
        for gs in st.groups:
            for a in (gs.x, gs.v, gs.w, gs.rot):
                if a is not None and not np.all(np.isfinite(np.asarray(a))):
                    return False
    return all(np.isfinite(m.diameter) for m in traj.metrics)


def _defect(model, gs):
    import numpy as np
    mats = model.rotations.to_matrices(gs.rot)
    gram = np.swapaxes(mats, 1, 2) @ mats
    return float(np.max(np.linalg.norm(gram - np.eye(mats.shape[1]), axis=(1, 2))))


def _max_err(scene_a, a, scene_b, b):
    import numpy as np
    ra, rb = scene_a.model.rotations, scene_b.model.rotations
    err = 0.0
    for ga, gb in zip(a.groups, b.groups):
        err = max(err, float(np.max(np.abs(ra.to_matrices(ga.rot) - rb.to_matrices(gb.rot)))),
                  float(np.max(np.abs(ga.x - gb.x))))
    return err


EXPLICIT = ("lie_euler", "lie_heun", "rkmk4", "euler_proj", "rk4_proj")


# ---------------------------------------------------------------------------------------------
# the extremes


def stiff_mass(ctx):
    from dataclasses import replace
    import numpy as np
    from ..core import METHODS, PolymatchError, simulate
    n = 6 if ctx.quick else 50
    kw = dict(count=n, seed=7, kappa=1.5, gamma=2.0)
    second = _scene(3, 2, mass=1e-8, t_end=2.0, **kw)
    lam = list(np.roots([1e-8, 2.0, 1.5])) + [-2.0 / 1e-8]

    def refusals():
        parts, ok = [], True
        for dt in (0.01, 0.05):
            for name in EXPLICIT:
                msg, limit = _refusal(second, name, dt)
                want = _rk_limit(METHODS[name].info.order, lam)
                good = msg is not None and "\n" not in msg and limit is not None and abs(limit / want - 1) < 5e-3
                ok &= good
                if dt == 0.01:
                    parts.append(f"{name} dt < {limit:.3g}" if limit else f"{name}: ran")
        return "all refuse (exit 2, one line): " + ", ".join(parts) + " (m/gamma = 5e-9)", ok

    ctx.check("m = 1e-8, dt = 0.01/0.05, explicit RK", "refuse: 'dt <' ~2..2.8 m/gamma", refusals)

    def verlet():
        msg, limit = _refusal(second, "lie_verlet", 0.02)
        want = 2.0 / np.sqrt(1.5 / 1e-8)
        ok = limit is not None and abs(limit / want - 1) < 5e-3
        return f"refuses: dt < {limit:.3g} = 2 sqrt(m/kappa); message blames 'damping stiff' (it is exact)", ok

    ctx.check("m = 1e-8, lie_verlet", "refuse at 2 sqrt(m/kappa)", verlet)

    t_end = 2.0 if ctx.quick else 10.0
    samples = list(np.arange(0.0, t_end + 1.0, 1.0))          # on every step grid below
    first = _scene(3, 1, t_end=t_end, samples=samples, **kw)
    ref = simulate(first, "rkmk4", 1e-3)
    dts = (0.04, 0.02) if ctx.quick else (0.04, 0.02, 0.01, 0.005)
    rows, errs = [], []

    def etd2():
        for dt in dts:
            a = simulate(_scene(3, 2, mass=1e-8, t_end=t_end, samples=samples, **kw), "etd2", dt)
            err = max(_max_err(first, ref.final, a.scene, a.final),
                      max(abs(p.diameter - q.diameter) for p, q in zip(a.metrics, ref.metrics)))
            errs.append(err)
            rows.append([f"{dt:g}", f"{err:.2e}", f"{errs[-2] / err:.2f}" if len(errs) > 1 else "-",
                         f"{a.wall_time:.2f}", "yes" if _finite(a) else "NO"])
        ratios = [p / q for p, q in zip(errs, errs[1:])]
        ok = errs[0] < 1e-3 and all(3.0 < r < 5.0 for r in ratios)
        return (f"runs; error vs (A-2) {errs[0]:.1e} at dt = {dts[0]:g} .. {errs[-1]:.1e} at dt = {dts[-1]:g}, "
                f"ratio per halving {min(ratios):.2f}-{max(ratios):.2f} (O(dt^2))"), ok

    ctx.check("m = 1e-8, etd2", "agrees with first order (A-2) to O(m/gamma) + O(dt^2)", etd2)
    ctx.detail(f"m = 1e-8: etd2 against the first-order model (A-2), N = {n}, t_end = {t_end:g} "
               "(reference rkmk4 dt = 1e-3 on the first-order scene)",
               ["dt", "max error (state, diameters)", "ratio", "wall s", "finite"], rows)

    def mass_sweep():
        out, ok = [], True
        prev = None
        for m in (1e-1, 1e-2, 1e-3, 1e-4):
            a = simulate(_scene(3, 2, mass=m, t_end=t_end, samples=samples, **kw), "etd2", 2.5e-3)
            err = _max_err(first, ref.final, a.scene, a.final)
            out.append(f"m = {m:g}: {err:.1e}")
            if prev is not None:
                ok &= 5 < prev / err < 20          # O(m/gamma)
            prev = err
        return "error vs (A-2) at dt = 2.5e-3: " + ", ".join(out) + " (O(m))", ok

    if not ctx.quick:
        ctx.check("m -> 0 sweep, etd2", "error O(m/gamma) (first-order limit)", mass_sweep)

    def auto_tolerance():
        scene = _scene(3, 2, mass=1e-8, t_end=1.0, **kw)
        scene = replace(scene, integrator=replace(scene.integrator, method="auto", tolerance=1e-6,
                                                  max_steps=100 if ctx.quick else 3000))
        try:
            traj = simulate(scene, samples=[0.0], keep_states=False)
        except PolymatchError as exc:
            return f"refused: '{exc}'", "\n" not in str(exc)
        return f"auto picks {traj.plan.name} and finishes ({traj.steps} steps)", traj.plan.name == "etd2"

    ctx.check("m = 1e-8 with a tolerance, integrator auto", "etd2, or a prompt refusal", auto_tolerance)


def undamped(ctx):
    import numpy as np
    from ..core import simulate
    t_end = 50.0 if ctx.quick else ctx.args.t_long
    dt = 0.1

    def scene():
        return _scene(2, 2, count=5, seed=11, gamma=0.0, mass=1.0, t_end=t_end, samples={"every": t_end / 200},
                      velocities={"angular": {"normal": 0.7}})

    rows = []
    results = {}
    for name in ("lie_verlet", "rkmk4", "etd2"):
        if ctx.quick and name == "rkmk4":
            continue
        def run(name=name):
            traj = simulate(scene(), name, dt)
            e = np.array([m.groups[0].energy for m in traj.metrics])
            dev = np.abs(e - e[0]) / e[0]
            k = len(dev) // 10
            results[name] = (dev[:k].max(), dev[-k:].max(), (e[-1] - e[0]) / e[0], traj)
            early, late, final, _ = results[name]
            rows.append([name, f"{early:.2e}", f"{late:.2e}", f"{final:+.2e}", traj.steps, f"{traj.wall_time:.2f}"])
            return early, late, traj
        if name == "lie_verlet":
            def verlet():
                early, late, traj = run()
                ok = late < 2.0 * early and max(early, late) < 2e-3 and _finite(traj)
                return (f"{traj.steps} steps: relative energy error <= {early:.1e} in the first tenth, {late:.1e} in the last "
                        "(bounded oscillation, no drift)"), ok
            ctx.check(f"gamma = 0, lie_verlet, t_end = {t_end:g}", "energy (Prop. 2.2 i) without secular drift",
                      verlet)
        else:
            def other(name=name):
                early, late, traj = run(name)
                return (f"energy drifts: {early:.1e} -> {late:.1e} (not symplectic; shown for contrast)",
                        _finite(traj))
            ctx.check(f"gamma = 0, {name}, t_end = {t_end:g}", "runs (stable), drifts: contrast", other)
    ctx.detail(f"gamma = 0: relative energy deviation, N = 5, d = 2, dt = {dt:g}, t_end = {t_end:g}",
               ["method", "max, first tenth", "max, last tenth", "E(t_end)/E0 - 1", "steps", "wall s"], rows)

    sc = _scene(2, 2, count=5, seed=11, gamma=0.0, mass=1.0, t_end=10.0)

    def refusals():
        parts, ok = [], True
        for name in ("lie_euler", "lie_heun", "euler_proj", "etd1"):
            msg, limit = _refusal(sc, name, 0.05)
            ok &= msg is not None and "gamma = 0" in msg and "\n" not in msg
            parts.append(f"{name}: " + (f"'dt < {limit:.3g}'" if limit else "no stable step"))
        return "refused: " + ", ".join(parts), ok

    ctx.check("gamma = 0, lie_euler/lie_heun/euler_proj/etd1", "refuse, naming gamma = 0 (one line)", refusals)

    def no_stable_step():
        msg, limit = _refusal(sc, "lie_euler", 0.05)
        return f"'{msg}'", "no stable step" in (msg or "") and not limit

    ctx.check("gamma = 0, methods with no stable step", "say 'no stable step'", no_stable_step)


def stiff_coupling(ctx):
    import numpy as np
    from ..core import METHODS, simulate
    n = 6 if ctx.quick else 100
    kappa = 1e4

    def scene(order, t_end, samples=None):
        return _scene(3, order, count=n, seed=7, kappa=kappa, mass=1.0, t_end=t_end, samples=samples)

    def refusals():
        parts, ok = [], True
        for order, dt in ((1, 0.01), (2, 0.05)):
            lam = [-kappa] if order == 1 else list(np.roots([1.0, 1.0, kappa])) + [-1.0]
            for name in EXPLICIT:
                msg, limit = _refusal(scene(order, 1.0), name, dt)
                want = _rk_limit(METHODS[name].info.order, lam)
                ok &= limit is not None and abs(limit / want - 1) < 5e-3
                if name == "rkmk4":
                    parts.append(f"order {order}: rkmk4 dt < {limit:.3g}")
        return "all refuse; " + ", ".join(parts) + " (2.785/kappa; 2.83/sqrt(kappa/m))", ok

    ctx.check("kappa = 1e4, explicit fixed step", "refuse beyond ~2.8/kappa", refusals)

    t_end = 5e-3
    sc = scene(1, t_end, samples=[0.0, 1e-3, t_end])
    ref = simulate(sc, "rkmk4", 2.5e-6)
    rows = []

    def compliant():
        errs = []
        for h in (1e-4, 5e-5, 2e-5) if ctx.quick else (1e-4, 5e-5, 2e-5, 1e-5):
            traj = simulate(sc, "rkmk4", h)
            err = _max_err(sc, traj.final, sc, ref.final)
            errs.append(err)
            rows.append(["rkmk4", f"h = {h:g} (h kappa = {h * kappa:g})", traj.steps, traj.rhs_evals, f"{err:.1e}",
                         f"{traj.wall_time:.2f}"])
        return f"rkmk4 error {errs[0]:.1e} at h kappa = 1 .. {errs[-1]:.1e} at h kappa = 0.1 or 0.2", errs[2] < 1e-6

    ctx.check("kappa = 1e4, rkmk4 at compliant h", "accurate vs reference (h = 2.5e-6)", compliant)

    def adaptive():
        out, ok = [], True
        for tol in (1e-6, 1e-8, 1e-10):
            traj = simulate(sc, "adaptive", tolerance=tol)
            err = _max_err(sc, traj.final, sc, ref.final)
            rows.append(["adaptive", f"tolerance {tol:g}", traj.steps, traj.rhs_evals, f"{err:.1e}",
                         f"{traj.wall_time:.2f}"])
            out.append(f"tol {tol:g}: {traj.steps} steps/{traj.rhs_evals} evals, error {err:.0e}")
            ok &= _finite(traj) and err < 100 * tol
        return "; ".join(out), ok

    ctx.check("kappa = 1e4, adaptive", "accurate; cost ~ t_end kappa / stability boundary", adaptive)
    ctx.detail(f"kappa = 1e4, first order, N = {n}, t_end = {t_end:g} (50 time constants 1/kappa): cost and "
               "error against rkmk4 h = 2.5e-6", ["method", "setting", "steps", "evaluations", "max error", "wall s"],
               rows)


def _exact_diameter(points):
    """Farthest pair: on the convex hull (d <= 3), else (or if Qhull balks) a blocked exact scan."""
    import numpy as np
    from scipy.spatial.distance import pdist
    p = np.asarray(points, dtype=float)
    p = p - p.mean(axis=0)
    if p.shape[1] <= 3:
        try:
            from scipy.spatial import ConvexHull
            return float(pdist(p[ConvexHull(p).vertices]).max())
        except Exception:          # degenerate cloud: fall through to the scan
            pass
    sq = np.einsum("ij,ij->i", p, p)
    best, pair = -1.0, (0, 0)
    for a in range(0, len(p), 1000):
        d2 = sq[a:a + 1000, None] + sq[None, :] - 2.0 * p[a:a + 1000] @ p.T
        k = int(np.argmax(d2))
        i, j = divmod(k, len(p))
        if d2[i, j] > best:
            best, pair = float(d2[i, j]), (a + i, j)
    return float(np.linalg.norm(p[pair[0]] - p[pair[1]]))


def large_n(ctx):
    import numpy as np
    from ..core import simulate
    n = 200 if ctx.quick else ctx.args.n_large
    rows = []

    def matching(sc, st):
        rots = sc.model.rotations.to_matrices(st.groups[0].rot)
        verts = st.groups[0].x[:, None, :] + np.einsum("nij,aj->nai", rots, sc.model.groups[0].reference)
        return max(_exact_diameter(verts[:, a, :]) for a in range(verts.shape[1]))

    for order, t_end in (((1, 30.0),) if ctx.quick else ((1, 40.0), (2, 60.0))):
        def run(order=order, t_end=t_end):
            sc = _scene(3, order, count=n, seed=3, t_end=t_end, samples={"every": 10.0}, mass=0.5,
                        centroids={"box": [-5.0, 5.0]}, velocities={"angular": {"normal": 0.5}})
            traj = simulate(sc, "rkmk4", 0.1)
            d0, dend = traj.metrics[0].diameter, traj.metrics[-1].diameter
            e0, eend = matching(sc, traj.states[0]), matching(sc, traj.final)
            worst = max(_defect(sc.model, s.groups[0]) for s in traj.states)
            rows.append([order, n, traj.steps, f"{d0:.3f}", f"{dend:.2e}", f"{traj.converged_at}", f"{worst:.1e}",
                         f"{traj.wall_time:.1f}"])
            ok = (_finite(traj) and traj.converged and abs(d0 - e0) <= 1e-12 * d0
                  and abs(dend - eend) <= 1e-12 * d0)
            return (f"{traj.steps} steps in {traj.wall_time:.1f} s; diameter {d0:.2f} -> {dend:.1e}, converged at "
                    f"t = {traj.converged_at}; metrics = exact farthest pair (differences {abs(d0 - e0):.0e}, "
                    f"{abs(dend - eend):.0e})"), ok
        ctx.check(f"N = {n}, order {order}, rkmk4 dt = 0.1", "full run converges; metrics finite and exact", run)
    ctx.detail(f"N = {n}, d = 3 (regular tetrahedra), rkmk4 dt = 0.1",
               ["order", "N", "steps", "D(0)", "D(t_end)", "converged at", "max orth. defect", "wall s"], rows)


def dim10(ctx):
    from ..core import simulate
    n = 4 if ctx.quick else 100
    for order in (1, 2):
        def run(order=order):
            sc = _scene(10, order, count=n, seed=7, t_end=40.0, samples={"every": 5.0}, mass=0.5,
                        velocities={"angular": {"normal": 0.5}})
            traj = simulate(sc, "rkmk4", 0.1)
            worst = max(_defect(sc.model, s.groups[0]) for s in traj.states)
            ok = _finite(traj) and worst < 1e-12 and traj.converged
            return (f"orthogonality defect <= {worst:.1e}; diameter {traj.metrics[0].diameter:.2f} -> "
                    f"{traj.diameters[-1]:.1e}, converged at t = {traj.converged_at} ({traj.wall_time:.1f} s)"), ok
        ctx.check(f"d = 10, N = {n}, order {order}", "stays in SO(10) to 1e-12; converges", run)


def long_horizon(ctx):
    import numpy as np
    from ..core import simulate
    t_end = 200.0 if ctx.quick else ctx.args.t_long
    rows = []
    runs = [(3, 1, "rkmk4", 2.5), (3, 1, "adaptive", 1e-8)] if ctx.quick else [
        (3, 1, "rkmk4", 2.5), (4, 1, "rkmk4", 2.5), (3, 2, "lie_verlet", 0.5), (3, 2, "etd2", 0.5),
        (3, 1, "adaptive", 1e-8), (3, 2, "adaptive", 1e-8)]
    for dim, order, method, h in runs:
        def run(dim=dim, order=order, method=method, h=h):
            sc = _scene(dim, order, count=6, seed=3, t_end=t_end, samples={"every": t_end / 100}, mass=1.0,
                        representation="matrix", velocities={"angular": {"normal": 0.5}})
            traj = simulate(sc, "adaptive", tolerance=h) if method == "adaptive" else simulate(sc, method, h)
            defects = [_defect(sc.model, s.groups[0]) for s in traj.states]
            t = np.array(traj.times)
            late = traj.diameters[t >= 100.0]
            rows.append([f"{dim}", order, method, f"{'tol' if method == 'adaptive' else 'dt'} {h:g}", traj.steps,
                         f"{defects[1]:.1e}", f"{defects[-1]:.1e}", f"{traj.converged_at}", f"{late.max():.1e}",
                         f"{traj.wall_time:.1f}"])
            ok = _finite(traj) and max(defects) < 1e-12 and late.max() < sc.tolerance
            return (f"{traj.steps} steps; orth. defect {defects[1]:.0e} -> {defects[-1]:.0e}; max diameter after "
                    f"t = 100: {late.max():.1e} (tolerance 1e-6)"), ok
        ctx.check(f"t_end = {t_end:g}, d = {dim}, order {order}, {method}",
                  "no orthogonality drift; converged stays converged", run)
    ctx.detail(f"long horizon t_end = {t_end:g}, N = 6, matrix representation",
               ["d", "order", "method", "setting", "steps", "orth. defect (first sample)", "orth. defect (t_end)",
                "converged at", "max D after t = 100", "wall s"], rows)


def huge_coords(ctx):
    import numpy as np
    from ..core import PolymatchError, load_scene, simulate
    n = 6 if ctx.quick else 1000
    t_end = 5.0 if ctx.quick else 20.0
    rng = np.random.default_rng(3)

    def placed(offset, pa, pb, dim, order, mixed):
        model = {"order": order, "kappa": 1.0, "gamma": 1.0}
        if order == 2:
            model["mass"] = 0.5
        groups = [{"name": "a", "shape": "triangle", "count": len(pa), "rotations": "uniform",
                   "centroids": {"points": (pa + offset).tolist()}}]
        if mixed:
            model.update(kappa_2=0.5, L=3.0)
            groups.append({"name": "b", "shape": "tetrahedron" if dim == 3 else "square", "count": len(pb),
                           "rotations": "uniform", "centroids": {"points": (pb + offset).tolist()}})
        return load_scene({"dimension": dim, "seed": 4, "model": model,
                           "time": {"t_end": t_end, "samples": {"every": 0.5}}, "groups": groups})

    for dim, order, mixed in ((2, 1, False), (3, 2, True)) if ctx.quick else ((2, 1, False), (3, 2, False),
                                                                              (3, 2, True)):
        def run(dim=dim, order=order, mixed=mixed):
            size = min(n, 200) if mixed else n          # F-2 pair forces cost O(N^2)
            pa = np.round(rng.uniform(-5, 5, (size, dim)) * 2 ** 10) / 2 ** 10
            pb = np.round(rng.uniform(-5, 5, (size, dim)) * 2 ** 10) / 2 ** 10
            far, near = placed(1e9, pa, pb, dim, order, mixed), placed(0.0, pa, pb, dim, order, mixed)
            tf, tn = simulate(far, "rkmk4", 0.05), simulate(near, "rkmk4", 0.05)
            diff = max(abs(gf.matching_diameter - gn.matching_diameter)
                       for mf, mn in zip(tf.metrics, tn.metrics) for gf, gn in zip(mf.groups, mn.groups))
            ok = _finite(tf) and diff <= 1e-12
            return (f"N = {size}{' + ' + str(size) if mixed else ''}: max diameter difference far - origin over {len(tf.metrics)} "
                    f"samples = {diff:.1e} (shape size 1); "
                    f"D(t_end) = {tf.diameters[-1]:.1e}"), ok
        ctx.check(f"centroids ~1e9, d = {dim}, order {order}{', mixed F-2' if mixed else ''}",
                  "diameters = translated scene's to 1e-12 of the shape", run)

    def explicit():
        import math
        tri = np.array([[0.0, 1.0], [-math.sqrt(3) / 2, -0.5], [math.sqrt(3) / 2, -0.5]])
        agents = [{"vertices": (tri @ np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]]).T
                                + np.array(c) + 1e9).tolist()}
                  for a, c in ((0.3, (0.0, 0.0)), (1.2, (3.0, -2.0)), (2.0, (-1.0, 4.0)))]
        try:
            load_scene({"dimension": 2, "groups": [{"name": "g", "shape": "triangle", "agents": agents}]})
        except PolymatchError as exc:
            return f"refused: '{exc}'", False
        return "loaded (mismatch judged against the coordinates' own resolution, ~1e-7)", True

    ctx.check("explicit vertices at 1e9", "load (within input precision 1e-7)", explicit)


def scale_ratios(ctx):
    import numpy as np
    from ..core import PolymatchError, simulate

    def scene(order, t_end=1.0, samples=None, max_steps=None):
        return _scene(2, order, count=6, seed=5, scales={"log_uniform": [1e-6, 1e6]}, mass=0.5, t_end=t_end,
                      samples=samples, shape="triangle", max_steps=max_steps)

    sc = scene(1)
    s = sc.model.groups[0].scales
    jac = (1.0 / len(s)) * (np.outer(1.0 / s, s) - np.diag(np.sum(s) / s))
    k = float(np.max(np.abs(np.linalg.eigvals(jac))))

    def refusals():
        parts, ok = [], True
        for order in (1, 2):
            for name in ("lie_euler", "rkmk4", "rk4_proj") + (("etd2", "lie_verlet") if order == 2 else ()):
                msg, limit = _refusal(scene(order), name, 0.05)
                ok &= msg is not None and "scale ratios" in msg
                if name == "rkmk4":
                    parts.append(f"order {order}: rkmk4 dt < {limit:.3g}")
        return (f"all refuse naming 's_k/s_i' (s_max/s_min = {s.max() / s.min():.1e}, stiffness {k:.2e}); "
                + ", ".join(parts)), ok

    ctx.check("scales 1e-6 .. 1e6 (F-1), explicit fixed step", "refuse naming the scale ratios", refusals)

    def compliant():
        t_end = 2e-7 if ctx.quick else 2e-6
        sc2 = scene(1, t_end=t_end, samples=[0.0, t_end / 2, t_end])
        ref = simulate(sc2, "rkmk4", 1.25e-10)
        run = simulate(sc2, "rkmk4", 1e-9)
        err = _max_err(sc2, run.final, sc2, ref.final)
        return f"rkmk4 h = 1e-9 (h k = {1e-9 * k:.2f}): error {err:.1e} vs h/8 over {run.steps} steps", err < 1e-9

    ctx.check("scales 1e-6 .. 1e6, compliant dt", "accurate vs reference", compliant)

    budget = 300 if ctx.quick else 20000

    def adaptive():
        sc3 = scene(1, max_steps=budget)
        try:
            simulate(sc3, "adaptive", tolerance=1e-8, keep_states=False, samples=[0.0])
        except PolymatchError as exc:
            msg = str(exc)
            return f"refuses before stepping: '{msg}'", "\n" not in msg and "stiff" in msg and "s_k/s_i" in msg
        return "finished", True

    ctx.check(f"scales 1e-6 .. 1e6, adaptive (max_steps {budget})",
              "a prompt one-line PolymatchError naming the stiffness", adaptive)


def equilibria(ctx):
    import math
    import numpy as np
    from ..core.simulate import convergence_verdict
    from ..core import simulate
    from dataclasses import replace

    def anti(rep, st):
        mats = rep.to_matrices(st.groups[0].rot)
        r = mats[0].T @ mats[1]
        return float(np.arcsin(min(1.0, np.linalg.norm(r - r.T) / (2 * math.sqrt(2)))))

    def splay(rep, st):
        mats = rep.to_matrices(st.groups[0].rot)
        th = np.arctan2(mats[:, 1, 0], mats[:, 0, 0])
        dev = np.angle(np.exp(1j * (th - th[0] - 2 * np.pi * np.arange(len(th)) / len(th))))
        return float(np.linalg.norm(dev - dev.mean()))

    cases = [("antipodal SO(2)", 2, "triangle", {"angles": [0.0, math.pi]}, anti, 1.0),
             ("antipodal SO(3)", 3, "tetrahedron", {"rotvecs": [[0, 0, 0], [0, 0, 3.141592653589793]]}, anti, 1.0),
             ("splay SO(2), N = 3", 2, "triangle", {"angles": [0.0, 2 * math.pi / 3, 4 * math.pi / 3]}, splay, 0.5)]
    rows = []
    m, gamma = 0.5, 1.0
    for name, dim, shape, rots, dev, c in cases[:1] if ctx.quick else cases:
        for order in (1,) if ctx.quick else (1, 2):
            reps = ("auto",) if ctx.quick else ("auto", "matrix")
            for rep in reps:
                def run(name=name, dim=dim, shape=shape, rots=rots, dev=dev, c=c, order=order, rep=rep):
                    rate = c if order == 1 else (-gamma + math.sqrt(gamma ** 2 + 4 * m * c)) / (2 * m)
                    sc = _scene(dim, order, count=len(next(iter(rots.values()))), shape=shape, rotations=rots,
                                representation=rep, mass=m, t_end=60.0 / rate, samples={"every": 0.25},
                                centroids={"box": [-1.0, 1.0]})
                    traj = simulate(sc, "rkmk4", 0.05)
                    t = np.array(traj.times)
                    eps = np.array([dev(sc.model.rotations, st) for st in traj.states])
                    # before the first exit from the linear regime (after escape eps returns to 0)
                    first_exit = t[np.argmax(eps >= 1e-3)] if np.any(eps >= 1e-3) else np.inf
                    w = (eps > 1e-11) & (eps < 1e-3) & (t < first_exit)
                    slope, icpt = np.polyfit(t[w], np.log(eps[w]), 1)
                    escape = float(t[np.argmax(eps > 0.5)]) if np.any(eps > 0.5) else None
                    rows.append([name, order, sc.model.rotations.name, f"{eps[0]:.1e}", f"{rate:.4f}", f"{slope:.4f}",
                                 f"{math.exp(icpt):.1e}", f"{escape:g}" if escape else "> t_end",
                                 f"{math.log(0.5 / math.exp(icpt)) / rate:.1f}",
                                 "yes" if traj.converged else "no"])
                    ok = _finite(traj) and abs(slope / rate - 1) < 0.02 and math.exp(icpt) < 1e-14
                    return (f"held to round-off; deviation grows at {slope:.4f} (linear rate {rate:.4f}) from "
                            f"{math.exp(icpt):.0e}; escapes at t = {escape}"), ok
                ctx.check(f"{name}, order {order}, {rep}", "reproduced; only round-off growth of the unstable mode",
                          run)
    ctx.detail("Non-consensus equilibria: deviation eps(t) from the equilibrium, fitted eps0 e^{rate t} for "
               "1e-11 < eps < 1e-3 (rkmk4, dt = 0.05, kappa = gamma = 1, m = 0.5)",
               ["equilibrium", "order", "representation", "eps(0)", "linear rate", "measured rate", "fitted eps0",
                "escape (eps > 0.5) at t", "predicted ln(0.5/eps0)/rate", "converged by t_end"], rows)

    def verdict():
        sc = _scene(2, 1, count=2, shape="triangle", rotations={"angles": [0.0, math.pi]}, t_end=10.0,
                    centroids={"points": [[-1.0, 0.0], [1.0, 0.0]]})
        traj = simulate(sc)
        code, msg = convergence_verdict(sc, traj.diameters[-1], traj.converged_at, traj.stationarity)
        code2, _ = convergence_verdict(replace(sc, expect_convergence=False), traj.diameters[-1], traj.converged_at,
                                       traj.stationarity)
        return f"exit {code} ('... not consensus ...'), exit {code2} with expected: false", \
            code == 3 and "not consensus" in msg and code2 == 0

    ctx.check("antipodal SO(2), CLI verdict at t_end = 10", "exit 3 naming the non-consensus equilibrium", verdict)


def d0_random(ctx):
    from ..core import simulate
    seeds = range(2) if ctx.quick else range(50)
    t_end = 40.0 if ctx.quick else 100.0
    for dim in (2, 3):
        def run(dim=dim):
            conv, d0s = 0, []
            for seed in seeds:
                sc = _scene(dim, 1, count=8, seed=seed, t_end=t_end, samples={"every": 10.0})
                traj = simulate(sc, "rkmk4", 0.1)
                d0s.append(traj.metrics[0].groups[0].rotation_diameter)
                conv += traj.converged
            return (f"{conv}/{len(seeds)} converge by t = {t_end:g}; D0 (rotation diameter) {min(d0s):.2f} .. "
                    f"{max(d0s):.2f}"), conv == len(seeds)
        ctx.check(f"D0 >= 1, uniform random, N = 8, d = {dim}", "converges (outside Thm 4.2)", run)


def coincident(ctx):
    import numpy as np
    from ..core import load_scene, simulate

    def scene(order, at, pert=0.0, t_end=10.0 if ctx.quick else 30.0):
        model = {"order": order, "kappa": 1.0, "gamma": 1.0, "kappa_2": 0.5, "L": 3.0}
        if order == 2:
            model["mass"] = 0.5
        groups = [{"name": n, "shape": s, "count": 4, "rotations": "uniform", "centroids": {"at": list(at)}}
                  for n, s in (("triangles", "triangle"), ("squares", "square"))]
        sc = load_scene({"dimension": 2, "seed": 4, "model": model,
                         "time": {"t_end": t_end, "samples": {"every": 0.5}}, "groups": groups})
        sc.initial.groups[0].x[0, 0] += pert
        return sc

    for order in (2,) if ctx.quick else (1, 2):
        for at in ((0.0, 0.0), (1e9, 1e9)):
            def run(order=order, at=at):
                traj = simulate(scene(order, at), "rkmk4", 0.05)
                sep = max(m.group_separation for m in traj.metrics)
                return f"finite; group separation stays {sep:g} (zero force at coincidence)", \
                    _finite(traj) and sep == 0.0
            ctx.check(f"coincident centroids (F-2), order {order}, at {at[0]:g}", "finite; stay together", run)
    rows = []

    def asym():
        ok = True
        for pert in (1e-12,) if ctx.quick else (1e-15, 1e-12, 1e-6):
            traj = simulate(scene(2, (0.0, 0.0), pert), "rkmk4", 0.05)
            seps = [m.group_separation for m in traj.metrics]
            t1 = next((t for t, s in zip(traj.times, seps) if s > 1.0), None)
            rows.append([f"{pert:g}", f"{seps[0]:.1e}", f"{t1}", f"{seps[-1]:.6f}", f"{traj.times[-1]:g}"])
            ok &= _finite(traj) and abs(seps[-1] - 3.0) < (1e-2 if ctx.quick else 1e-5)
        return "any asymmetry separates the groups to L = 3 within a few time units", ok

    ctx.check("coincident centroids + asymmetry 1e-15 .. 1e-6", "groups separate to L", asym)

    def pairs():
        rng = np.random.default_rng(3)
        pts = np.round(rng.uniform(-5, 5, (6, 2)) * 2 ** 10) / 2 ** 10     # exact next to 1e9 too

        def make(off):
            model = {"order": 2, "mass": 0.5, "kappa": 1.0, "gamma": 1.0, "kappa_2": 0.5, "L": 3.0}
            groups = [{"name": "a", "shape": "triangle", "count": 6, "rotations": "uniform",
                       "centroids": {"points": (pts + off).tolist()}},
                      {"name": "b", "shape": "square", "count": 6, "rotations": "uniform",
                       "centroids": {"points": (pts[::-1] + off).tolist()}}]
            return load_scene({"dimension": 2, "seed": 4, "model": model,
                               "time": {"t_end": 20.0, "samples": {"every": 0.5}}, "groups": groups})

        far, near = simulate(make(1e9), "rkmk4", 0.05), simulate(make(0.0), "rkmk4", 0.05)
        diff = max(abs(x - y) for x, y in zip(far.diameters, near.diameters))
        seps = [t.metrics[-1].group_separation for t in (far, near)]
        ok = _finite(far) and _finite(near) and all(abs(x - 3.0) < 1e-3 for x in seps)
        return (f"each centroid of group a sits on one of group b (group centres coincide): round-off picks the "
                f"directions, so the copy at 1e9 differs from the one at 0 by up to {diff:.2f} in D on the way; "
                f"both end at separation {seps[0]:.6f} / {seps[1]:.6f} (L = 3)"), ok

    ctx.check("coincident pairs across groups, translated copy", "finite; separate to L; path decided by round-off",
              pairs)
    ctx.detail("Coincident centroids: one centroid moved by eps (second order, kappa_2 = 0.5, L = 3)",
               ["eps", "separation at t = 0", "separation > 1 at t", "separation at t_end", "t_end"], rows)


def collinear(ctx):
    import numpy as np
    from scipy.spatial.transform import Rotation
    from ..core import PolymatchError, load_scene, simulate
    rows = []

    def attempt(dim, height):
        rng = np.random.default_rng(0)
        tri = np.zeros((3, dim))
        tri[1, 0], tri[2, 0], tri[2, 1] = 1.0, 0.5, height
        if dim == 2:
            a = rng.uniform(-np.pi, np.pi, 5)
            rots = np.stack([np.stack([np.cos(a), -np.sin(a)], -1), np.stack([np.sin(a), np.cos(a)], -1)], -2)
        else:
            rots = Rotation.random(5, random_state=1).as_matrix()
        verts = np.einsum("nij,aj->nai", rots, tri) + rng.uniform(-3, 3, (5, dim))[:, None, :]
        try:
            sc = load_scene({"dimension": dim, "time": {"t_end": 40.0, "samples": {"every": 10.0}},
                             "groups": [{"name": "s", "agents": [{"vertices": v.tolist()} for v in verts]}]})
        except PolymatchError as exc:
            return f"refused: {str(exc)[:90]}...", None
        st = sc.initial.groups[0]
        rebuilt = st.x[:, None, :] + np.einsum("nij,aj->nai", sc.model.rotations.to_matrices(st.rot),
                                               sc.model.groups[0].reference) + sc.origin
        traj = simulate(sc, "rkmk4", 0.05)
        return (f"vertex error {np.max(np.abs(rebuilt - verts)):.0e}, D(40) = {traj.diameters[-1]:.0e}"
                + (" (rotation not unique note)" if sc.notes else "")), traj.converged

    heights = (1e-9, 0.0) if ctx.quick else (1e-3, 1e-6, 1e-9, 1e-12, 1e-15, 0.0)
    for dim in (2, 3):
        def run(dim=dim):
            outcomes = {}
            for h in heights:
                text, conv = attempt(dim, h)
                outcomes[h] = conv
                rows.append([dim, f"{h:g}", text])
            bad = [h for h, c in outcomes.items() if not c]
            return ("all decompose and converge" if not bad else
                    "refused or not converged at heights " + ", ".join(f"{h:g}" for h in bad)), not bad
        ctx.check(f"nearly collinear triangle, d = {dim}, heights 1e-3 .. 0", "decomposes; converges", run)
    ctx.detail("Nearly collinear triangles (length 1, height h), explicit vertices, 5 agents, first order",
               ["d", "height", "outcome"], rows)


def dt_gt_t_end(ctx):
    import warnings
    from ..core import METHODS, simulate
    for order in (1, 2):
        def run(order=order):
            names, ok = [], True
            for name, meth in METHODS.items():
                if order not in meth.info.models:
                    continue
                sc = _scene(3, order, count=4, seed=2, t_end=0.3, velocities={"angular": {"normal": 0.5}})
                with warnings.catch_warnings(record=True) as caught:
                    warnings.simplefilter("always")
                    traj = simulate(sc, name, 5.0)
                ok &= (len(caught) == 1 and "larger than t_end" in str(caught[0].message) and traj.steps == 1
                       and _finite(traj) and abs(traj.final.t - 0.3) < 1e-15)
                names.append(name)
            return f"one warning and one step of t_end for {', '.join(names)}", ok
        ctx.check(f"dt = 5 > t_end = 0.3, order {order}", "warning; one step of t_end; finite", run)


def one_agent(ctx):
    from ..core import METHODS, simulate
    dims = (2, 3) if ctx.quick else (2, 3, 10)
    for order in (1, 2):
        def run(order=order):
            ok, count = True, 0
            for dim in dims:
                for name in [n for n, m in METHODS.items() if order in m.info.models] + ["adaptive"]:
                    sc = _scene(dim, order, count=1, t_end=1.0, velocities={"angular": {"normal": 0.5},
                                                                             "centroid": {"normal": 0.5}})
                    traj = (simulate(sc, "adaptive", tolerance=1e-8) if name == "adaptive"
                            else simulate(sc, name, 0.05))
                    ok &= _finite(traj) and traj.converged_at == 0.0 and max(traj.diameters) == 0.0
                    count += 1
            where = ", ".join(map(str, dims))
            return f"{count} runs (d = {where}, every integrator): diameter 0, converged at t = 0", ok
        ctx.check(f"one agent, order {order}", "trivially converged, no crash", run)


FUNCTIONS = {"stiff_mass": stiff_mass, "undamped": undamped, "stiff_coupling": stiff_coupling,
             "large_n": large_n, "dim10": dim10, "long_horizon": long_horizon, "huge_coords": huge_coords,
             "scale_ratios": scale_ratios, "equilibria": equilibria, "d0_random": d0_random,
             "coincident": coincident, "collinear": collinear, "dt_gt_t_end": dt_gt_t_end, "one_agent": one_agent}


def run(args, log):
    import time
    from .report import Report
    keys = list(KEYS)
    if getattr(args, "only", None):
        wanted = [k.strip() for k in args.only.split(",") if k.strip()]
        unknown = [k for k in wanted if k not in FUNCTIONS]
        if unknown:
            from ..core import ParameterError
            raise ParameterError(f"--only: unknown extreme {unknown[0]!r}; known: {', '.join(KEYS)}")
        keys = [k for k in keys if k in wanted]
    ctx = Ctx(args.quick, log, args)
    t0 = time.perf_counter()
    for key in keys:
        log(f"extremes: {key}")
        FUNCTIONS[key](ctx)
    report = Report(NAME, "Stability at the extremes (`polymatch bench extremes`)")
    passed = sum(r[3] == "pass" for r in ctx.rows)
    report.text(f"{len(ctx.rows)} expectations over {len(keys)} extremes: {passed} pass, "
                f"{len(ctx.rows) - passed} fail; {time.perf_counter() - t0:.1f} s."
                + (" **--quick: toy sizes.**" if args.quick else ""))
    report.table(["extreme", "expectation", "what happened", "pass/fail", "wall s"], ctx.rows,
                 caption="Extremes: expectation and outcome")
    for caption, header, rows in ctx.details:
        report.table(header, rows, caption=caption)
    return report
