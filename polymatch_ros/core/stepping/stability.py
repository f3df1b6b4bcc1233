"""Linear stability at consensus: which fixed steps a method may take on a scene.

Each scene linearises at consensus into small test systems (``test_matrices``);
a method's step h is stable when its amplification there has spectral radius
<= 1.  ``check_stability`` refuses a step beyond the limit with a
``StabilityError`` that names the limit and what causes it.
"""

import numpy as np

from ..errors import StabilityError
from ..model import Model
from .solver import Method

# These tolerances must agree with one another: the limit search stops at LIMIT_RTOL,
# far above RADIUS_SLACK, so a limit it finds is an interval, not round-off.
#: relative step beyond h that must be stable too (a mode on |R| = 1 would never decay)
BEYOND = 1e-6
#: round-off allowed in a spectral radius that is exactly 1
RADIUS_SLACK = 1e-12
#: relative width at which the bisection for the largest stable step stops
LIMIT_RTOL = 1e-6
#: limits with h * rate below this are checked for growth inside (RADIUS_SLACK artefacts)
TINY_LIMIT = 1e-2
#: scale ratios within this of 1 are congruent (no torque weights to report)
RATIO_SLACK = 1e-12



def test_matrices(model: Model) -> list[tuple[str, np.ndarray, str]]:
    """Linearisations at consensus a fixed-step method must keep bounded: (label, matrix, cause).

    Rotations in algebra coordinates xi: first order xi' = -k xi / gamma, second order
    m xi'' = -gamma xi' - k xi, with k = kappa * max_i(mean s / s_i) (F-1 weights; 1 if
    congruent).  On a communication graph k = kappa * max |lambda| of its Laplacian with the
    F-1 weights (``Graph.coupling_rate``; 1 for the complete graph).  Integrated (F-2)
    centroids add k = kappa * rate + kappa_2.  The mean mode (k = 0) carries the pure damping
    -gamma/m.  Exactly solved centroids contribute nothing.
    """
    out = []
    m, gamma = model.mass, model.gamma
    centroid_rate = 0.0
    for g in model.groups:
        centroid_rate = max(centroid_rate, 1.0 if g.graph is None else g.graph.coupling_rate())
        if g.graph is not None:
            w = g.graph.coupling_rate(g.scales)
            weights = f" on the {g.graph.kind} graph (Laplacian spectral radius {w:.3g})"
        else:
            w = 1.0 if g.scales is None else float(np.mean(g.scales) / np.min(g.scales))
            weights = (f"; scale ratios make the torque weights s_k/s_i up to {w:.3g}"
                       if w > 1.0 + RATIO_SLACK else "")
        k = model.kappa * w
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
        k = model.kappa * centroid_rate + model.kappa_2
        a = (np.array([[-k / gamma]]) if model.order == 1
             else np.array([[0.0, 1.0], [-k / m, -gamma / m]]))
        out.append(("centroids", a, f"the centroid coupling kappa + kappa_2 = {k:.3g}"))
    if model.order == 2 and gamma > 0:
        out.append(("damping", np.array([[0.0, 1.0], [0.0, -gamma / m]]),
                    f"m/gamma = {m / gamma:.3g} makes the damping stiff"))
    return out


def _stable(method, h, a):
    """Stable just beyond h too: a damped mode exactly on |R| = 1 would never decay."""
    return method.spectral_radius(h * (1.0 + BEYOND), a) <= 1.0 + RADIUS_SLACK


def _limit(method, a, upper):
    """Largest stable h <= upper for one test matrix; 0 when none is (e.g. Euler, gamma = 0)."""
    if _stable(method, upper, a):
        return upper
    lo, hi = 0.0, upper
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if _stable(method, mid, a):
            lo = mid
        else:
            hi = mid
        if hi - lo <= LIMIT_RTOL * hi:
            break
    rate = float(np.max(np.abs(np.linalg.eigvals(a))))
    # a suspiciously small "limit" may be RADIUS_SLACK, not a stability interval: if the
    # method still amplifies well inside it, it grows at every h (Euler or Heun with gamma = 0)
    if rate > 0 and lo * rate < TINY_LIMIT and method.spectral_radius(0.5 * lo, a) > 1.0:
        return 0.0
    return lo


def max_stable_dt(method: Method, model: Model, upper: float) -> float:
    """Largest h <= upper that is linearly stable on every test matrix (0: none is)."""
    return min(_limit(method, a, upper) for _, a, _ in test_matrices(model))


def check_stability(method: Method, model: Model, dt: float) -> None:
    """Refuse a step beyond the method's linear stability limit, naming the limit and its cause."""
    if model.order not in method.info.models:
        raise StabilityError(f"{method.name} integrates only the "
                             f"{'second' if 2 in method.info.models else 'first'}-order model "
                             f"(model.order = {model.order})", method=method.name, dt=dt)
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
    fields = {"method": method.name, "dt": dt, "limit": limit, "cause": cause}
    if limit <= 0:
        undamped = model.order == 2 and model.gamma == 0
        what = "gamma = 0: the undamped oscillation grows at every dt" if undamped else cause
        raise StabilityError(f"{method.name} has no stable step for this scene ({what}{hint})",
                             **fields)
    raise StabilityError(f"{method.name} is unstable at dt = {dt:g}: its linear stability limit "
                         f"here is dt < {limit:.3g} ({cause}{hint}); use a smaller dt", **fields)
