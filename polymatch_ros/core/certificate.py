"""A certificate of matching: the paper's bounds, where their hypotheses hold, as a time.

From the state at t0 the certificate says whether the matching diameter (``metrics``:
max_{i,j,a} |x^i_a - x^j_a|, x^i_a = xbar_i + O_i r_a) is *guaranteed* to fall below a
tolerance, and by when.  Only results whose hypotheses are checked on the state are used:

First order (A-2) on the complete graph, any d: Theorem 4.2 with Props 2.1 (ii) and 2.2 (ii).
In this package (A-2) reads xbar_i' = c (mean xbar - xbar_i), O_i' = c/(2N) (S O_i^T -
O_i S^T) O_i with c = kappa/gamma (``model``: the paper's (B-3) with m = 0 divided by gamma),
so the paper's bounds hold with kappa replaced by c:

    centroids  D_x(t0 + tau) = D_x(t0) e^{-c tau}                      (Prop 2.1 (ii), exact)
    rotations  D_O(t0 + tau) <= D_O e^{-c tau} / (1 - D_O + D_O e^{-c tau})
               (D_O = max |O_i - O_j|_F at t0 < 1)     (Prop 2.2 (ii): D' <= -c D (1 - D))

Vertices: for one pair and vertex a,

    |x^i_a - x^j_a| <= |xbar_i - xbar_j| + |(O_i - O_j) r_a|
                    <= D_x + ||O_i - O_j||_2 R <= D_x + R D_O / sqrt 2,     R = max_a |r_a|,

since O_i - O_j = O_i (I - U), U = O_i^T O_j in SO(d), has the singular values |1 - lambda|
over U's eigenvalues lambda: the non-real ones come in conjugate pairs and -1 has even
multiplicity (det U = 1), so every non-zero singular value appears at least twice and
||.||_2^2 <= ||.||_F^2 / 2.  Hence the matching diameter is at most
D_x(t) + R D_O(t) / sqrt 2 for all t >= t0.

d = 2, first order, on a connected undirected graph (the complete graph included), congruent
polytopes, all phases within an open half-circle (arc length A0 < pi): the identical Kuramoto
oscillators' phase cohesiveness (e.g. Doerfler & Bullo, Automatica 50, 2014).  Write the
coupling as theta_i' = (c / b_i) sum_k w_ik sin(theta_k - theta_i) with w symmetric, b > 0
(``Graph.symmetric_pair``: w = a/N_g, b = 1; or, normalised by degree, w = a, b = deg), K the
Laplacian of w and lambda_2 > 0 its smallest non-zero eigenvalue relative to diag(b).  Then
(1) the arc is non-increasing (the leading phase has theta' <= 0, the trailing >= 0);
(2) V = sum_i b_i (theta_i - theta_b)^2, theta_b the b-weighted mean (constant), obeys
V' = -c sum_{i,k} w_ik (theta_i - theta_k) sin(theta_i - theta_k)
   <= -2 c sinc(A0) theta^T K theta <= -2 c sinc(A0) lambda_2 V   (x sin x >= sinc(A0) x^2);
(3) the arc A <= sqrt(2 V / min b), and |(O_i - O_j) r| = 2 |sin(A_ij / 2)| |r|.  The centroids
obey the linear version: V_x(t) <= V_x e^{-2 c lambda_2 tau} and their hull never grows (on the
complete graph Prop 2.1 (ii) is exact).  So the matching diameter is at most
D_x(tau) + 2 R sin(min(A0, sqrt(2 V e^{-2 c sinc(A0) lambda_2 tau} / min b)) / 2).

Everything else is "not certified", with the reason: the second-order model (Prop 2.2 (i)
gives no rate; the centroids' rate of Prop 2.1 (i) is reported), D_O >= 1 in d >= 3 (or outside
a half-circle in 2-D), similar (F-1) or mixed (F-2) ensembles (the paper proves nothing),
directed or disconnected graphs, graphs in d >= 3.

Over ``diameters.EXACT_PAIRS_UP_TO`` agents the diameters D_x and D_O come from
``core.diameters`` in O(N log N): exact where the convex hull or the phases' arc gives them,
else as bounds.  The bounds above increase with D_x and D_O, so an upper bound in their place
still bounds the diameter (the certificate's line names the values that are bounds); a lower
bound D_O >= 1 refuses Thm 4.2, and bounds that straddle 1 leave it undecided (not
certified).  Independent groups (no F-2 potential)
are certified each; the ensemble's time is the latest.  ``CertificateKeeper`` grants a run's
certificate once and never withdraws it (a breach of the bound is reported, not hidden).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .diameters import EXACT_PAIRS_UP_TO, Diameter, circle_arc, diameter, planar_rotation_diameter
from .graph import DENSE_SPECTRUM_LIMIT

if TYPE_CHECKING:
    from .model import Group, GroupState, Model, State

LOHE = "Thm 4.2, Props 2.1 (ii), 2.2 (ii)"
HALF_CIRCLE = "phases within an open half-circle on a connected graph, 2-D Kuramoto"
#: relative excess of an observed diameter over the bound that counts as a breach: far above
#: the integrators' error, far below any real departure from the model
BREACH = 1e-3


@dataclass(frozen=True)
class LoheBound:
    """Thm 4.2: D_x e^{-c tau} + R/sqrt 2 * D_O e^{-c tau} / (1 - D_O + D_O e^{-c tau})."""

    rate: float          # c = kappa / gamma
    centroids: float     # D_x at t0
    rotations: float     # D_O = max |O_i - O_j|_F at t0, < 1
    radius: float        # R = max_a |r_a|
    bounded: tuple[str, ...] = ()  # values above that are upper bounds, not exact diameters

    def __call__(self, tau: float | np.ndarray) -> float | np.ndarray:
        e = np.exp(-self.rate * np.asarray(tau, dtype=float))
        rot = self.rotations * e / (1.0 - self.rotations + self.rotations * e)
        return self.centroids * e + self.radius / math.sqrt(2.0) * rot


@dataclass(frozen=True)
class HalfCircleBound:
    """2-D, phases in an arc < pi on a connected undirected graph (module docstring)."""

    rate: float          # c lambda_2
    centroids: float     # D_x at t0
    centroid_energy: float  # sqrt(2 V_x / min b); 0 with exact_centroids
    arc: float           # A0 < pi
    phase_energy: float  # sqrt(2 V / min b)
    sinc: float          # sin(A0) / A0
    radius: float
    exact_centroids: bool  # complete graph: D_x e^{-c tau} (Prop 2.1 (ii))
    bounded: tuple[str, ...] = ()  # values above that are upper bounds, not exact diameters

    def __call__(self, tau: float | np.ndarray) -> float | np.ndarray:
        tau = np.asarray(tau, dtype=float)
        if self.exact_centroids:
            cent = self.centroids * np.exp(-self.rate * tau)
        else:
            cent = np.minimum(self.centroids, self.centroid_energy * np.exp(-self.rate * tau))
        arc = np.minimum(self.arc, self.phase_energy * np.exp(-self.sinc * self.rate * tau))
        return cent + 2.0 * self.radius * np.sin(arc / 2.0)


Bound = LoheBound | HalfCircleBound


@dataclass(frozen=True)
class Certificate:
    """Whether the matching diameter is guaranteed below ``tolerance``, and from when.

    ``time``: absolute time by which it is (None: not certified); ``theorem``: what is cited;
    ``reason``: why not (or the hypotheses checked); ``centroid_rate``: the centroids'
    exponential rate (Prop 2.1) where known; ``bounds``: each group's bound, tau after t0.
    """

    certified: bool
    reason: str
    theorem: str
    t0: float
    time: float | None
    tolerance: float
    centroid_rate: float | None = None
    bounds: tuple[Bound, ...] = ()

    def bound(self, t: float | np.ndarray) -> float | np.ndarray:
        """Upper bound on the matching diameter at t >= t0 (max over the groups)."""
        if not self.bounds:
            raise ValueError("a certificate that is not granted bounds nothing")
        tau = np.asarray(t, dtype=float) - self.t0
        vals = np.max([np.asarray(b(tau)) for b in self.bounds], axis=0)
        return float(vals) if np.ndim(vals) == 0 else vals

    def line(self) -> str:
        """One line for people: ``certified: ... by t <= T (...)`` or ``not certified: ...``;
        a bound built on diameters' upper bounds (large groups) says which."""
        if self.certified and self.time is not None:
            bounded = [text for b in self.bounds for text in b.bounded]
            upper = (f"; from upper bounds, not exact diameters (over {EXACT_PAIRS_UP_TO} "
                     f"agents): {', '.join(bounded)}" if bounded else "")
            return (f"certified: matching diameter < {self.tolerance:g} by t <= "
                    f"{ceil_significant(self.time)} ({self.theorem}{upper})")
        return f"not certified: {self.reason}"


def ceil_significant(x: float, digits: int = 3) -> str:
    """x rounded *up* to ``digits`` significant digits (a printed guarantee is never early)."""
    if x <= 0 or not math.isfinite(x):
        return f"{x:g}"
    scale = 10.0 ** (math.floor(math.log10(x)) - digits + 1)
    up = math.ceil(x / scale * (1 - 1e-12)) * scale
    return f"{up:.{max(digits - 1 - math.floor(math.log10(up)), 0)}f}"


def centroid_rate(model: Model) -> float:
    """The centroids' exponential rate on the complete graph (Prop 2.1).

    First order: kappa/gamma (exact).  Second order: (gamma - sqrt(gamma^2 - 4 m kappa))/(2m)
    when gamma^2 >= 4 m kappa, else gamma/(2m) (Prop 2.1 (i), a rate up to a constant)."""
    if model.order == 1:
        return model.kappa / model.gamma
    m, g, k = model.mass, model.gamma, model.kappa
    disc = g * g - 4.0 * m * k
    if disc >= 0:
        root = g + math.sqrt(disc)
        return 2.0 * k / root if root > 0 else 0.0  # (g - sqrt(disc)) / (2m), no cancellation
    return g / (2.0 * m)


def _not(reason: str, t0: float, tolerance: float, rate: float | None = None) -> Certificate:
    return Certificate(False, reason, "", t0, None, tolerance, rate)


def certify(model: Model, state: State, tolerance: float) -> Certificate:
    """The certificate of ``state`` (a whole ensemble at ``state.t``) for ``model``."""
    t0 = float(state.t)
    rate = centroid_rate(model) if all(g.graph is None for g in model.groups) else None
    if model.order == 2:
        where = "" if rate is None else f"; centroids contract at rate {rate:.3g} (Prop. 2.1 (i))"
        return _not("second-order model: the paper gives no rotation bound (Prop. 2.2 (i) has "
                    "no rate)" + where, t0, tolerance, rate)
    if model.inter_group:
        return _not("mixed ensemble (F-2): the inter-group potential is outside the paper's "
                    "results", t0, tolerance, rate)
    bounds: list[Bound] = []
    cited: set[str] = set()
    for g, gs in zip(model.groups, state.all_groups()):
        got = _group_bound(model, g, gs)
        if isinstance(got, str):
            named = f"group {g.name!r}: " if len(model.groups) > 1 else ""
            return _not(named + got, t0, tolerance, rate)
        bounds.append(got)
        cited.add(LOHE if isinstance(got, LoheBound) else HALF_CIRCLE)
    taus = [_time_below(b, tolerance) for b in bounds]
    if any(tau is None for tau in taus):
        return _not(f"kappa = {model.kappa:g}: the bound "
                    f"{max(float(b(0.0)) for b in bounds):.3g} does not decay below "
                    f"{tolerance:g}", t0, tolerance, rate)
    time = t0 + max(tau for tau in taus if tau is not None)
    return Certificate(True, "hypotheses hold at t0", "; ".join(sorted(cited)), t0, time,
                       tolerance, rate, tuple(bounds))


def _group_bound(model: Model, g: Group, gs: GroupState) -> Bound | str:
    """The group's bound, or why none applies (first-order model, no F-2 potential)."""
    if g.scales is not None:
        return "similar polytopes (F-1): the paper proves nothing for them"
    graph = g.graph
    if graph is not None and graph.directed:
        return "directed graph: no result is cited for it"
    if graph is not None and graph.dynamic:
        return ("proximity graph: its edges change with the state, and switching-graph "
                "consensus needs the union graph connected over time, which no bound here checks")
    if graph is not None and int(graph.components.max(initial=0)) > 0:
        return "disconnected graph: its components need not match"
    radius = float(np.max(np.linalg.norm(g.reference, axis=1), initial=0.0))
    c = model.kappa / model.gamma
    lohe_reason = None
    if graph is None:
        d_o = rotation_diameter(model, gs)
        if d_o.upper < 1.0:
            d_x = diameter(gs.x)
            bounded = tuple(f"{name} <= {d.upper:.3g}"
                            for name, d in (("D_x", d_x), ("D0", d_o)) if not d.exact)
            return LoheBound(c, d_x.upper, d_o.upper, radius, bounded)
        if d_o.lower >= 1.0:
            shown = f"D0 = {d_o.upper:.3g}" if d_o.exact else f"D0 >= {d_o.lower:.3g} (a bound)"
            lohe_reason = f"{shown} >= 1 (Thm 4.2 needs max |O_i - O_j|_F < 1)"
        else:
            lohe_reason = (f"{d_o.text('D0')}: the O(N) bounds over {EXACT_PAIRS_UP_TO} agents "
                           f"do not decide Thm 4.2's max |O_i - O_j|_F < 1")
    if model.dim != 2:
        return lohe_reason or f"graph in d = {model.dim}: no result is cited (only for 2-D)"
    half = _half_circle(model, g, gs, c, radius)
    if isinstance(half, str):
        return half if lohe_reason is None else f"{lohe_reason}; {half}"
    return half


def rotation_diameter(model: Model, gs: GroupState) -> Diameter:
    """max_{i,j} |O_i - O_j|_F of a group: exact, or bounds over EXACT_PAIRS_UP_TO agents
    (in 2-D exact from the phases' arc while it is under a half-circle)."""
    grp = model.rotations
    if model.dim == 2 and grp.count(gs.rot) > EXACT_PAIRS_UP_TO:
        mats = grp.to_matrices(gs.rot)
        return planar_rotation_diameter(np.arctan2(mats[:, 1, 0], mats[:, 0, 0]))
    return diameter(grp.flat(gs.rot))


def _half_circle(model: Model, g: Group, gs: GroupState, c: float,
                 radius: float) -> HalfCircleBound | str:
    """The 2-D half-circle bound of group g, or why not (phases spread over >= pi)."""
    mats = model.rotations.to_matrices(gs.rot)
    theta = np.arctan2(mats[:, 1, 0], mats[:, 0, 0])
    lifted, arc = circle_arc(theta)
    if arc >= math.pi:
        return f"phases spread over {arc:.3g} >= pi (not within an open half-circle)"
    if g.graph is None:
        b = np.ones(g.size)
        lam = 1.0       # K = (N I - 1 1^T)/N relative to I: every non-zero eigenvalue is 1
    else:
        if g.size > DENSE_SPECTRUM_LIMIT and "laplacian_modes" not in g.graph.__dict__:
            return (f"graph of {g.size} > {DENSE_SPECTRUM_LIMIT} agents: its lambda_2 "
                    f"(O(N^3)) is not computed for a certificate")
        _, b = g.graph.symmetric_pair()
        lams = g.graph.laplacian_modes[0]
        lam = float(np.min(lams[lams > 0], initial=np.inf))   # connected: one zero mode
        lam = 1.0 if not math.isfinite(lam) else lam          # one agent: nothing to contract
    energy_o = _spread(lifted[:, None], b)
    energy_x = 0.0 if g.graph is None else _spread(gs.x, b)
    sinc = math.sin(arc) / arc if arc > 0 else 1.0
    d_x = diameter(gs.x)
    bounded = () if d_x.exact else (f"D_x <= {d_x.upper:.3g}",)
    return HalfCircleBound(c * lam, d_x.upper, energy_x, arc, energy_o, sinc, radius,
                           g.graph is None, bounded)


def _spread(values: np.ndarray, b: np.ndarray) -> float:
    """sqrt(2 V / min b), V = sum_i b_i |v_i - v_b|^2 (v_b the b-weighted mean)."""
    mean = (b @ values) / b.sum()
    dev = values - mean
    return math.sqrt(2.0 * float(b @ np.einsum("ij,ij->i", dev, dev)) / float(b.min()))


def _time_below(bound: Bound, tolerance: float) -> float | None:
    """The least tau >= 0 with bound(tau) <= tolerance (bounds are non-increasing); None: never."""
    if float(bound(0.0)) <= tolerance:
        return 0.0
    if not bound.rate > 0 or not math.isfinite(1.0 / bound.rate):
        return None
    hi = 1.0 / bound.rate
    while float(bound(hi)) > tolerance:
        hi *= 2.0
        if hi > 1e300:
            return None
    from scipy.optimize import brentq  # slow to import: a monitor that certifies nothing skips it

    step = 1e-12 * hi
    tau = float(brentq(lambda s: float(bound(s)) - tolerance, 0.0, hi, xtol=step, rtol=1e-14))
    while float(bound(tau)) > tolerance:      # the root's right side: a guarantee is never early
        tau += step
    return tau


class CertificateKeeper:
    """A run's certificate: evaluated on each observed state until granted, then kept.

    A granted certificate is a theorem about the model's flow: it is never withdrawn.  If an
    observed diameter exceeds its bound by more than ``BREACH`` (relative), the run is not the
    model's flow (e.g. a state changed from outside); ``breach`` records (t, observed, bound)
    so that it is reported, not hidden.
    """

    def __init__(self, tolerance: float) -> None:
        self.tolerance = tolerance
        self.current: Certificate | None = None
        self.breach: tuple[float, float, float] | None = None

    @property
    def granted(self) -> bool:
        return self.current is not None and self.current.certified

    def observe(self, model: Model, state: State, diameter: float) -> bool:
        """Take an observed state (and its matching diameter); True if there is news to publish:
        the first certificate, a newly granted one, a changed refusal, or a first breach."""
        if self.current is not None and self.current.certified:
            bound = float(self.current.bound(state.t))
            if self.breach is None and diameter > bound * (1.0 + BREACH):
                self.breach = (float(state.t), float(diameter), bound)
                return True
            return False
        new = certify(model, state, self.tolerance)
        changed = self.current is None or new.certified or new.reason != self.current.reason
        self.current = new
        return changed

    def refuse(self, t: float, reason: str) -> bool:
        """Record that no certificate can be evaluated (``reason``) unless one is granted."""
        if self.granted:
            return False
        changed = self.current is None or self.current.reason != reason
        self.current = _not(reason, t, self.tolerance)
        return changed
