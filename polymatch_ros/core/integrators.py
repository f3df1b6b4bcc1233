"""Fixed-step integrators: a registry of named steppers with order, stage count and stability.

Every stepper is a *generator*: ``method.step(system, state, h)`` yields each
stage state whose mean field it needs, receives the ensemble for that stage
(full group arrays), and returns the new state.  The centralised simulator
answers with its own arrays; a ROS agent in lockstep publishes its rows and
answers with what its peers sent.  One stepper serves both, which is why the
distributed trajectory equals the centralised one to round-off.

Families
--------
lie          Runge-Kutta-Munthe-Kaas: stages O_i = psi(Theta_i) O_n with Theta_i in so(d),
             k_i = dpsi^{-1}_{Theta_i}(W(O_i)).  Rotations stay in SO(d) to round-off
             (Lemma 2.1) with no projection.  psi = exp (angles in 2-D) or Cayley (d >= 3).
projection   Classical RK in the embedding R^{d x d}, then the polar factor (baselines).
exponential  For the second-order model (A-1) with stiff damping m/gamma -> 0: the damping
             is integrated exactly (scalar phi-functions), the coupling explicitly.  Runs at
             ordinary dt when m = 1e-8 and tends to the first-order model (A-2).
splitting    Strang splitting damp/kick/drift/kick/damp.  For gamma = 0 it is symplectic
             (the Cayley drift is the exact flow of a modified kinetic energy), so the energy
             of Proposition 2.2 has no secular drift.

Centroids that decouple (one group, or no inter-group potential) are advanced by
the exact flow of Proposition 2.1 inside every method; only F-2 centroids are
integrated with the method's own stages.
"""

import math
from dataclasses import dataclass

import numpy as np

from .errors import StabilityError
from .model import GroupState, State


@dataclass(frozen=True)
class MethodInfo:
    name: str
    order: int
    stages: int           # right-hand-side evaluations per step
    rounds: int           # exchange rounds per step in lockstep (FSAL methods: fewer than stages)
    family: str
    models: tuple         # model orders the method accepts
    summary: str


class Method:
    info: MethodInfo

    @property
    def name(self):
        return self.info.name

    def step(self, system, state, h):
        raise NotImplementedError

    def spectral_radius(self, h, a):
        """Spectral radius of the step's amplification on the linear test system y' = a y."""
        raise NotImplementedError


# ---------------------------------------------------------------------------------------------
# helpers on per-group stage data


def _nonempty(system, gs):
    return gs is not None and system.group.count(gs.rot) > 0


def _lincomb(base, h, coefs, terms):
    """base + h * sum coefs[j] * terms[j] (skipping zero coefficients); base may be None (zero)."""
    out = base
    for c, t in zip(coefs, terms):
        if c != 0.0 and t is not None:
            out = (h * c) * t if out is None else out + (h * c) * t
    return out


def _exact_centroids(system, y, coupling, h):
    """Proposition 2.1 flow of every local group's centroids over h (from the stage-1 mean field)."""
    out = []
    for gi, gs in enumerate(y.groups):
        out.append(system.exact_centroids(gi, gs, coupling, h) if _nonempty(system, gs) else (gs.x, gs.v))
    return out


def rk_stability(a, b, z):
    """R(z) = 1 + z b^T (I - z A)^{-1} 1 for an explicit tableau, vectorised over complex z."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    z = np.atleast_1d(np.asarray(z, dtype=complex))
    s = len(b)
    out = np.empty_like(z)
    for n, zz in enumerate(z):
        k = np.linalg.solve(np.eye(s) - zz * a, np.ones(s))
        out[n] = 1.0 + zz * (b @ k)
    return out


# ---------------------------------------------------------------------------------------------
# Runge-Kutta-Munthe-Kaas


class RKMK(Method):
    """Runge-Kutta-Munthe-Kaas method of a given explicit tableau (rotations via psi = exp / Cayley)."""

    def __init__(self, name, a, b, order, summary):
        self.a = [list(map(float, row)) for row in a]
        self.b = list(map(float, b))
        self.info = MethodInfo(name, order, len(b), len(b), "lie", (1, 2), summary)

    def _stage(self, system, y, h, row, ks):
        model = system.model
        groups, thetas = [], []
        for gi, gs in enumerate(y.groups):
            if not _nonempty(system, gs):
                groups.append(gs)
                thetas.append(None)
                continue
            kk = [k[gi] for k in ks]
            theta = _lincomb(None, h, row, [k[0] for k in kk])
            rot = gs.rot if theta is None else system.group.retract(theta, gs.rot)
            x, v, w = gs.x, gs.v, gs.w
            if not model.centroids_exact:
                x = _lincomb(gs.x, h, row, [k[1] for k in kk])
                if model.order == 2:
                    v = _lincomb(gs.v, h, row, [k[2] for k in kk])
            if model.order == 2:
                w = _lincomb(gs.w, h, row, [k[3] for k in kk])
            groups.append(GroupState(x, rot, v, w))
            thetas.append(theta)
        return thetas, State(y.t, tuple(groups))

    def step(self, system, y, h):
        model = system.model
        ks = []
        centroids = None
        for i in range(len(self.b)):
            if i == 0:
                stage, thetas = y, None
            else:
                thetas, stage = self._stage(system, y, h, self.a[i][:i], ks)
            coupling = yield from system.evaluate(stage, first_stage=(i == 0))
            if i == 0 and model.centroids_exact:
                centroids = _exact_centroids(system, y, coupling, h)
            ks.append(system.in_chart(system.rates(stage, coupling), thetas))
        thetas, end = self._stage(system, y, h, self.b, ks)
        return _finish(y, end, h, centroids)

    def spectral_radius(self, h, a):
        lam = np.linalg.eigvals(np.atleast_2d(a))
        return float(np.max(np.abs(rk_stability(self.a, self.b, h * lam))))


def _finish(y, end, h, centroids):
    groups = []
    for gi, gs in enumerate(end.groups):
        if centroids is not None:
            x, v = centroids[gi]
            gs = GroupState(x, gs.rot, v, gs.w)
        groups.append(gs)
    return State(y.t + h, tuple(groups))


# ---------------------------------------------------------------------------------------------
# classical RK + projection (baselines)


class ProjectedRK(Method):
    """Classical explicit RK on O' = W O in R^{d x d}, polar projection at the end of each step."""

    def __init__(self, name, a, b, order, summary):
        self.a = [list(map(float, row)) for row in a]
        self.b = list(map(float, b))
        self.info = MethodInfo(name, order, len(b), len(b), "projection", (1, 2), summary)

    def _combine(self, system, y, h, row, ks, project):
        model = system.model
        grp = system.group
        groups = []
        for gi, gs in enumerate(y.groups):
            if not _nonempty(system, gs):
                groups.append(gs)
                continue
            kk = [k[gi] for k in ks]
            rot = _lincomb(gs.rot, h, row, [k[0] for k in kk])
            if project:
                rot = grp.project(rot)
            x, v, w = gs.x, gs.v, gs.w
            if not model.centroids_exact:
                x = _lincomb(gs.x, h, row, [k[1] for k in kk])
                if model.order == 2:
                    v = _lincomb(gs.v, h, row, [k[2] for k in kk])
            if model.order == 2:
                w = _lincomb(gs.w, h, row, [k[3] for k in kk])
            groups.append(GroupState(x, rot, v, w))
        return State(y.t, tuple(groups))

    def step(self, system, y, h):
        model = system.model
        grp = system.group
        if grp.name == "angle":
            raise TypeError(f"{self.name} needs the matrix representation of SO(2)")
        ks = []
        centroids = None
        for i in range(len(self.b)):
            stage = y if i == 0 else self._combine(system, y, h, self.a[i][:i], ks, False)
            coupling = yield from system.evaluate(stage, first_stage=(i == 0))
            if i == 0 and model.centroids_exact:
                centroids = _exact_centroids(system, y, coupling, h)
            rates = system.rates(stage, coupling)
            ks.append([None if r is None else (grp.tangent(r[0], gs.rot),) + tuple(r[1:])
                       for r, gs in zip(rates, stage.groups)])
        end = self._combine(system, y, h, self.b, ks, True)
        return _finish(y, end, h, centroids)

    spectral_radius = RKMK.spectral_radius


# ---------------------------------------------------------------------------------------------
# exponential integrators for stiff damping


def phi_functions(z):
    """(e^z, phi_1(z), phi_2(z), phi_3(z)) for real z, accurate for all z <= 0 and small z > 0."""
    z = float(z)
    if abs(z) < 1.0:
        phis = []
        for k in (1, 2, 3):
            term = 1.0 / math.factorial(k)
            total = term
            for j in range(1, 30):
                term *= z / (j + k)
                total += term
            phis.append(total)
        return math.exp(z), phis[0], phis[1], phis[2]
    e = math.exp(z)
    p1 = math.expm1(z) / z
    p2 = (p1 - 1.0) / z
    p3 = (p2 - 0.5) / z
    return e, p1, p2, p3


class ExponentialLie(Method):
    """Exponential Lie-Euler (order 1) and ETD2-Lie (order 2) for the second-order model (A-1).

    With lambda = gamma/m and N(O) = kappa/(2Nm)(S O^T - O S^T), the damping is solved exactly:
        W(t) = e^{-lambda t} W_n + int_0^t e^{-lambda (t-s)} N(s) ds,   O_{n+1} = psi(int_0^h W) O_n,
    with N frozen (order 1) or linear between N(O_n) and N(O_pred) (order 2, Cox-Matthews ETD2RK):
        W_{n+1} = e W_n + h phi1 N_n + h phi2 (N_p - N_n)
        Theta   = h phi1 W_n + h^2 phi2 N_n + h^2 phi3 (N_p - N_n)
    As m -> 0 this tends to Heun's method for the first-order model (A-2); stable at any m.
    """

    def __init__(self, order):
        name = "etd1" if order == 1 else "etd2"
        summary = ("exponential Lie-Euler: damping exact, coupling frozen; stiff m/gamma"
                   if order == 1 else
                   "ETD2-Lie: damping exact, coupling linear in time; stiff m/gamma -> first-order limit")
        self.info = MethodInfo(name, order, order, order, "exponential", (2,), summary)

    def _forces(self, system, stage, coupling):
        m = system.model
        out = []
        for gi, gs in enumerate(stage.groups):
            if not _nonempty(system, gs):
                out.append(None)
                continue
            n_rot = system.rotation_rate(gi, gs.rot, coupling) / m.mass
            n_x = None if m.centroids_exact else system.centroid_force(gi, gs.x, coupling) / m.mass
            out.append((n_rot, n_x))
        return out

    def step(self, system, y, h):
        m = system.model
        grp = system.group
        e, p1, p2, p3 = phi_functions(-m.gamma * h / m.mass)
        c1 = yield from system.evaluate(y, first_stage=True)
        centroids = _exact_centroids(system, y, c1, h) if m.centroids_exact else None
        f1 = self._forces(system, y, c1)
        pred = []
        for gs, f in zip(y.groups, f1):
            if f is None:
                pred.append(gs)
                continue
            theta = h * p1 * gs.w + h * h * p2 * f[0]
            w = e * gs.w + h * p1 * f[0]
            x, v = gs.x, gs.v
            if f[1] is not None:
                x = gs.x + h * p1 * gs.v + h * h * p2 * f[1]
                v = e * gs.v + h * p1 * f[1]
            pred.append(GroupState(x, grp.retract(theta, gs.rot), v, w))
        pred = State(y.t, tuple(pred))
        if self.info.order == 1:
            return _finish(y, pred, h, centroids)
        c2 = yield from system.evaluate(pred)
        f2 = self._forces(system, pred, c2)
        out = []
        for gs, a, b in zip(y.groups, f1, f2):
            if a is None:
                out.append(gs)
                continue
            dn = b[0] - a[0]
            theta = h * p1 * gs.w + h * h * (p2 * a[0] + p3 * dn)
            w = e * gs.w + h * (p1 * a[0] + p2 * dn)
            x, v = gs.x, gs.v
            if a[1] is not None:
                dx = b[1] - a[1]
                x = gs.x + h * p1 * gs.v + h * h * (p2 * a[1] + p3 * dx)
                v = e * gs.v + h * (p1 * a[1] + p2 * dx)
            out.append(GroupState(x, grp.retract(theta, gs.rot), v, w))
        return _finish(y, State(y.t, tuple(out)), h, centroids)

    def spectral_radius(self, h, a):
        """Apply the scheme to x' = v, v' = -lambda v + n x (the 2x2 test system a)."""
        a = np.atleast_2d(np.asarray(a, dtype=float))
        lam, n = -a[1, 1], a[1, 0]
        e, p1, p2, p3 = phi_functions(-lam * h)
        amp = np.empty((2, 2))
        for col, (x0, v0) in enumerate(((1.0, 0.0), (0.0, 1.0))):
            n1 = n * x0
            xp = x0 + h * p1 * v0 + h * h * p2 * n1
            vp = e * v0 + h * p1 * n1
            if self.info.order == 2:
                dn = n * xp - n1
                xp = x0 + h * p1 * v0 + h * h * (p2 * n1 + p3 * dn)
                vp = e * v0 + h * (p1 * n1 + p2 * dn)
            amp[:, col] = (xp, vp)
        return float(np.max(np.abs(np.linalg.eigvals(amp))))


# ---------------------------------------------------------------------------------------------
# symplectic splitting for the second-order model


class LieVerlet(Method):
    """Damp(h/2) Kick(h/2) Drift(h) Kick(h/2) Damp(h/2), with a Cayley/exp drift O <- psi(h W) O.

    Second order; one mean-field evaluation per step (the last kick's is the next step's
    first: FSAL, cached on the returned state).  With gamma = 0 every sub-step is a
    symplectic map, so the energy of Proposition 2.2 oscillates at O(h^2) without drift.
    """

    info = MethodInfo("lie_verlet", 2, 1, 1, "splitting", (2,),
                      "Strang splitting damp/kick/drift/kick/damp; symplectic for gamma = 0, "
                      "one exchange per step")

    def step(self, system, y, h):
        m = system.model
        grp = system.group
        damp = math.exp(-m.gamma * h / (2.0 * m.mass))
        c0 = yield from system.evaluate(y, first_stage=True)
        centroids = _exact_centroids(system, y, c0, h) if m.centroids_exact else None
        mid = []
        half_v = []
        for gi, gs in enumerate(y.groups):
            if not _nonempty(system, gs):
                mid.append(gs)
                half_v.append(None)
                continue
            w = damp * gs.w + (0.5 * h / m.mass) * system.rotation_rate(gi, gs.rot, c0)
            rot = grp.retract(h * w, gs.rot)
            if centroids is not None:
                x, v = centroids[gi]
                hv = None
            else:
                hv = damp * gs.v + (0.5 * h / m.mass) * system.centroid_force(gi, gs.x, c0)
                x, v = gs.x + h * hv, hv
            mid.append(GroupState(x, rot, v, w))
            half_v.append(hv)
        mid = State(y.t + h, tuple(mid))
        c1 = yield from system.evaluate(mid, first_stage=True)
        out = []
        for gi, (gs, hv) in enumerate(zip(mid.groups, half_v)):
            if not _nonempty(system, gs):
                out.append(gs)
                continue
            w = damp * (gs.w + (0.5 * h / m.mass) * system.rotation_rate(gi, gs.rot, c1))
            v = gs.v
            if hv is not None:
                v = damp * (hv + (0.5 * h / m.mass) * system.centroid_force(gi, gs.x, c1))
            out.append(GroupState(gs.x, gs.rot, v, w))
        return State(y.t + h, tuple(out), coupling=c1)

    def spectral_radius(self, h, a):
        a = np.atleast_2d(np.asarray(a, dtype=float))
        lam, n = -a[1, 1], a[1, 0]
        damp = math.exp(-lam * h / 2.0)
        amp = np.empty((2, 2))
        for col, (x0, v0) in enumerate(((1.0, 0.0), (0.0, 1.0))):
            v = damp * v0 + 0.5 * h * n * x0
            x = x0 + h * v
            v = damp * (v + 0.5 * h * n * x)
            amp[:, col] = (x, v)
        return float(np.max(np.abs(np.linalg.eigvals(amp))))


# ---------------------------------------------------------------------------------------------
# registry

_RK4_A = [[0, 0, 0, 0], [0.5, 0, 0, 0], [0, 0.5, 0, 0], [0, 0, 1, 0]]
_RK4_B = [1 / 6, 1 / 3, 1 / 3, 1 / 6]

METHODS = {
    m.name: m for m in (
        RKMK("lie_euler", [[0]], [1], 1, "Lie-Euler: O <- psi(h W(O)) O"),
        RKMK("lie_heun", [[0, 0], [1, 0]], [0.5, 0.5], 2, "Munthe-Kaas Heun (RK2)"),
        RKMK("rkmk4", _RK4_A, _RK4_B, 4, "Munthe-Kaas classical RK4 (Cayley/exp coordinates)"),
        ProjectedRK("euler_proj", [[0]], [1], 1, "explicit Euler in R^{dxd} + polar projection (baseline)"),
        ProjectedRK("rk4_proj", _RK4_A, _RK4_B, 4, "classical RK4 in R^{dxd} + polar projection (baseline)"),
        ExponentialLie(1),
        ExponentialLie(2),
        LieVerlet(),
    )
}


def get_method(name):
    try:
        return METHODS[name]
    except KeyError:
        known = ", ".join(sorted(METHODS) + ["adaptive"])
        raise StabilityError(f"unknown integrator {name!r}; known: {known}") from None


# ---------------------------------------------------------------------------------------------
# linear stability at consensus


def test_matrices(model):
    """Linearisations at consensus that a fixed-step method must keep bounded: (label, matrix, cause).

    Rotations in algebra coordinates xi: first order xi' = -k xi / gamma, second order
    m xi'' = -gamma xi' - k xi, with k = kappa * max_i(mean s / s_i) (F-1 weights; 1 if
    congruent).  Integrated (F-2) centroids add k = kappa + kappa_2.  The mean mode (k = 0)
    carries the pure damping -gamma/m.  Exactly solved centroids contribute nothing.
    """
    out = []
    m, gamma = model.mass, model.gamma
    for g in model.groups:
        w = 1.0 if g.scales is None else float(np.mean(g.scales) / np.min(g.scales))
        k = model.kappa * w
        weights = f"; scale ratios make the torque weights s_k/s_i up to {w:.3g}" if w > 1.0 + 1e-12 else ""
        if model.order == 1:
            out.append(("rotations", np.array([[-k / gamma]]),
                        f"the coupling sets the rate kappa/gamma = {k / gamma:.3g}{weights}"))
        else:
            a = np.array([[0.0, 1.0], [-k / m, -gamma / m]])
            if gamma * gamma >= 4.0 * m * k:          # over-damped: the fast mode is the damping
                what = f"m/gamma = {m / gamma:.3g} makes the damping stiff"
            else:
                what = (f"the coupling kappa/m = {k / m:.3g} makes the rotations oscillate at "
                        f"{np.sqrt(k / m - (gamma / (2 * m)) ** 2):.3g} rad/s")
            out.append(("rotations", a, what + weights))
    if not model.centroids_exact:
        k = model.kappa + model.kappa_2
        a = np.array([[-k / gamma]]) if model.order == 1 else np.array([[0.0, 1.0], [-k / m, -gamma / m]])
        out.append(("centroids", a, f"the centroid coupling kappa + kappa_2 = {k:.3g}"))
    if model.order == 2 and gamma > 0:
        out.append(("damping", np.array([[0.0, 1.0], [0.0, -gamma / m]]),
                    f"m/gamma = {m / gamma:.3g} makes the damping stiff"))
    return out


def _stable(method, h, a):
    """Stable just beyond h too: a damped mode exactly on |R| = 1 would never decay."""
    return method.spectral_radius(h * (1.0 + 1e-6), a) <= 1.0 + 1e-12


def _limit(method, a, upper):
    """Largest stable h <= upper for one test matrix; 0 when no step is stable (e.g. Euler, gamma = 0)."""
    if _stable(method, upper, a):
        return upper
    lo, hi = 0.0, upper
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if _stable(method, mid, a):
            lo = mid
        else:
            hi = mid
        if hi - lo <= 1e-6 * hi:
            break
    rate = float(np.max(np.abs(np.linalg.eigvals(a))))
    # a suspiciously small "limit" may be the 1e-12 slack, not a stability interval: if the
    # method still amplifies well inside it, it grows at every h (Euler or Heun with gamma = 0)
    if rate > 0 and lo * rate < 1e-2 and method.spectral_radius(0.5 * lo, a) > 1.0:
        return 0.0
    return lo


def max_stable_dt(method, model, upper):
    """Largest h <= upper that is linearly stable on every test matrix (0: none is)."""
    return min(_limit(method, a, upper) for _, a, _ in test_matrices(model))


def check_stability(method, model, dt):
    """Refuse a step beyond the method's linear stability limit, naming the limit and its cause."""
    if model.order not in method.info.models:
        raise StabilityError(f"{method.name} integrates only the "
                             f"{'second' if 2 in method.info.models else 'first'}-order model "
                             f"(model.order = {model.order})")
    limits = [(_limit(method, a, dt), label, cause) for label, a, cause in test_matrices(model)]
    limit, label, cause = min(limits, key=lambda x: x[0])
    if limit >= dt:
        return
    if method.info.family == "splitting" and label != "damping" and "damping stiff" in cause:
        # the splitting integrates the damping exactly: what binds is the stiff coupling
        cause = cause.replace(f"m/gamma = {model.mass / model.gamma:.3g} makes the damping stiff",
                              f"kappa/m = {model.kappa / model.mass:.3g} makes the coupling stiff")
    advice = []
    stiff_damping = model.order == 2 and model.gamma > 0 and model.mass / model.gamma < dt
    if stiff_damping and method.name != "etd2":
        advice.append("etd2 integrates the damping exactly")
    if model.order == 2 and model.gamma == 0 and method.name != "lie_verlet":
        advice.append("lie_verlet is symplectic")
    hint = f"; {'; '.join(advice)}" if advice else ""
    if limit <= 0:
        what = "gamma = 0: the undamped oscillation grows at every dt" if model.order == 2 and model.gamma == 0 \
            else cause
        raise StabilityError(f"{method.name} has no stable step for this scene ({what}{hint})")
    raise StabilityError(f"{method.name} is unstable at dt = {dt:g}: its linear stability limit here is "
                         f"dt < {limit:.3g} ({cause}{hint}); use a smaller dt")
