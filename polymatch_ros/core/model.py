"""The paper's models as vectorised right-hand sides, split into a mean field and a local part.

Notation (paper): agent i of group g has centroid xbar_i in R^d, rotation
O_i in SO(d) and, for the second-order model, velocities xbar_i' and the
spatial angular velocity W_i = O_i' O_i^T (skew).  With O' = W O one has
O'' O^T + O' O'^T = W', so the rotation equations become

    (A-1)  m W_i' = -gamma W_i + kappa/(2 N) (S O_i^T - O_i S^T)
    (A-2)    W_i  =        kappa/(2 gamma N) (S O_i^T - O_i S^T)         (m = 0)

with S = sum_k O_k (the mean field: O(N d^3) instead of O(N^2 d^3)).

    (F-1)  similar polytopes: torque weights s_k / s_i, i.e. S = sum_k s_k O_k and a factor 1/s_i.
    (F-2)  mixed ensembles: kappa (kappa_1) couples centroids and rotations inside each group;
           kappa_2 couples centroids across groups through V = kappa_2/2 (|x - y| - L)^2,
           generalised to any number of groups by summing over every other group h with
           weight kappa_2 / N_h.

Centroids never couple to rotations, so centroid and rotation parts are
evaluated separately.  Inside one group without an inter-group potential the
centroid equations are linear and ``CentroidFlow`` solves them exactly
(Proposition 2.1).

Every quantity an agent needs from the others is collected by ``System.couple``
from an *ensemble* (full group arrays in agent-index order).  The centralised
simulator passes its own arrays; a ROS agent passes the arrays it assembled
from its peers' messages.  Both then run the same code.
"""

from dataclasses import dataclass, field, replace

import numpy as np

from .errors import SceneError
from .so import RotationGroup


@dataclass(frozen=True)
class Group:
    """One congruent (or similar) sub-ensemble sharing a reference shape."""

    name: str
    size: int                      # N_g
    reference: np.ndarray          # (n, d) centred r_a
    edges: tuple
    scales: np.ndarray = None      # (N_g,) s_i for similar ensembles (F-1); None = congruent
    start: int = 0                 # global index of the group's first agent

    @property
    def indices(self):
        return range(self.start, self.start + self.size)


@dataclass(frozen=True)
class Model:
    """Model parameters and structure; what the scene requires and nothing more."""

    dim: int
    order: int                     # 1, 2
    kappa: float
    gamma: float
    mass: float
    groups: tuple
    rotations: RotationGroup
    kappa_2: float = 0.0
    L: float = 0.0
    #: "exact": decoupled centroids follow Proposition 2.1's closed form; "integrated": the
    #: integrator's stages carry them (the full model, kept to show the reduction is exact)
    centroids: str = "exact"

    @property
    def n_agents(self):
        return sum(g.size for g in self.groups)

    @property
    def inter_group(self):
        """True when the F-2 inter-group potential is active."""
        return self.kappa_2 != 0.0 and len(self.groups) > 1

    @property
    def centroids_exact(self):
        """Centroids decouple into linear consensus per group: solved in closed form."""
        return not self.inter_group and self.centroids == "exact"

    def group_of(self, agent):
        for gi, g in enumerate(self.groups):
            if g.start <= agent < g.start + g.size:
                return gi, agent - g.start
        raise IndexError(f"agent {agent} is not in the scene (0..{self.n_agents - 1})")


@dataclass(slots=True)
class GroupState:
    """Rows of one group: centroid offsets x (n, d), rotations, and velocities (second order)."""

    x: np.ndarray
    rot: object
    v: np.ndarray = None
    w: object = None


@dataclass(slots=True)
class State:
    """An ensemble (or an agent's local rows of it) at time t.

    ``coupling`` caches the mean field evaluated at exactly this state, so a
    method whose last stage is the next step's first (FSAL) does not exchange twice.
    """

    t: float
    groups: tuple
    coupling: object = field(default=None, repr=False)


@dataclass(slots=True)
class Request:
    """A stage whose mean field is needed: the driver answers with the ensemble's arrays."""

    stage: State
    boundary: bool
    fields: tuple


@dataclass(slots=True)
class GroupCoupling:
    """What agent i needs from its group: S, N, and the centroid mean (and mean velocity)."""

    s: object
    n: int
    mean_x: np.ndarray = None
    mean_v: np.ndarray = None


@dataclass(slots=True)
class Coupling:
    groups: tuple
    centroids: tuple = None        # every group's full centroid array (F-2 only)


class CentroidFlow:
    """Exact flow of m x'' = -gamma x' + kappa (mu - x) over a step h (Proposition 2.1).

    The mean mu moves by its own momentum (kappa = 0 mode), each deviation
    x_i - mu by the damped oscillator with stiffness kappa.  For m = 0 the
    deviation decays as exp(-kappa h / gamma) and mu is constant.  Formulas are
    written with phi_1(z) = expm1(z)/z so they stay accurate for m -> 0, near
    critical damping, and for gamma = 0.
    """

    def __init__(self, mass, gamma, kappa):
        self.mass, self.gamma, self.kappa = float(mass), float(gamma), float(kappa)
        self._cache = {}

    @staticmethod
    def _roots(m, gamma, k):
        """Roots of m l^2 + gamma l + k = 0, computed without cancellation."""
        disc = gamma * gamma - 4.0 * m * k
        if disc >= 0:
            sq = np.sqrt(disc)
            q = -0.5 * (gamma + sq)
            fast = q / m
            slow = k / q if q != 0 else 0.0
            return complex(fast), complex(slow)
        sq = np.sqrt(-disc)
        return complex(-gamma, sq) / (2 * m), complex(-gamma, -sq) / (2 * m)

    def _matrix(self, k, h):
        m, gamma = self.mass, self.gamma
        l1, l2 = self._roots(m, gamma, k)
        delta = l1 - l2
        e1, e2 = np.exp(l1 * h), np.exp(l2 * h)
        z = delta * h
        phi1 = np.expm1(z) / z if abs(z) > 1e-12 else 1.0 + z / 2
        p = h * e2 * phi1                    # (e1 - e2) / (l1 - l2)
        if abs(z) > 1.0:                     # well separated roots: no cancellation
            xx = (l1 * e2 - l2 * e1) / delta
            vv = (l1 * e1 - l2 * e2) / delta
        else:
            xx = e2 - l2 * p
            vv = e2 + l1 * p
        vx = -(k / m) * p
        return np.array([[xx, p], [vx, vv]]).real

    def propagator(self, h):
        """(mean 2x2, deviation 2x2) for the second-order model; scalars for the first."""
        key = float(h)
        if key not in self._cache:
            if self.mass == 0.0:
                self._cache[key] = (1.0, float(np.exp(-self.kappa * h / self.gamma)))
            else:
                self._cache[key] = (self._matrix(0.0, h), self._matrix(self.kappa, h))
            if len(self._cache) > 64:
                self._cache.pop(next(iter(self._cache)))
        return self._cache[key]

    def advance(self, x, v, mean_x, mean_v, h):
        """New (x, v) of the given rows, from the group means at the start of the step."""
        p0, pk = self.propagator(h)
        dx = x - mean_x
        if self.mass == 0.0:
            return mean_x + pk * dx, None
        dv = v - mean_v
        mx = p0[0, 0] * mean_x + p0[0, 1] * mean_v
        mv = p0[1, 0] * mean_x + p0[1, 1] * mean_v
        return (mx + pk[0, 0] * dx + pk[0, 1] * dv,
                mv + pk[1, 0] * dx + pk[1, 1] * dv)


def pair_force(x, y, kappa_2, L, chunk=1 << 20):
    """F-2 force on each row of x from the centroids y of another group (N_y = len(y)).

        F_i = kappa_2 / N_y  sum_l (|y_l - x_i| - L) (y_l - x_i) / |y_l - x_i|

    which is -grad_x of (kappa_2 / N_y) sum_l V(x_i, y_l).  At exactly coincident
    centroids the direction is undefined (the paper's force is 0/0); we take the
    force of such a pair to be zero, the average of the force over all directions
    of approach.  It is finite everywhere, never NaN, and the pair separates as
    soon as any other agent moves either centroid.
    """
    out = np.zeros_like(x)
    if len(y) == 0 or len(x) == 0:
        return out
    rows = max(1, chunk // (len(y) * x.shape[1]))
    for a in range(0, len(x), rows):
        diff = y[None, :, :] - x[a:a + rows, None, :]
        r = np.sqrt(np.sum(diff * diff, axis=2))
        with np.errstate(divide="ignore", invalid="ignore"):
            coef = np.where(r > 0, (r - L) / np.where(r > 0, r, 1.0), 0.0)
        out[a:a + rows] = np.einsum("ij,ijk->ik", coef, diff)
    return out * (kappa_2 / len(y))


class System:
    """The model evaluated for a set of local rows against an ensemble.

    ``rows[g]`` are the local rows of group g (indices inside the group);
    ``None`` means all rows (the centralised simulator).
    """

    def __init__(self, model, rows=None):
        self.model = model
        self.group = model.rotations
        self.rows = tuple(None for _ in model.groups) if rows is None else tuple(rows)
        self.flows = tuple(CentroidFlow(model.mass, model.gamma, model.kappa) for _ in model.groups)
        # kappa/(2N) (second order) or kappa/(2 gamma N) (first order), N supplied per evaluation
        self._rate_scale = model.kappa / 2.0 if model.order == 2 else model.kappa / (2.0 * model.gamma)
        self._inv_scales = []
        for g, r in zip(model.groups, self.rows):
            if g.scales is None:
                self._inv_scales.append(None)
            else:
                s = g.scales if r is None else g.scales[np.asarray(r)]
                self._inv_scales.append(1.0 / s)

    # -- what must be exchanged ---------------------------------------------
    def exchange_fields(self, first_stage):
        """Fields of a stage that other agents need (the distributed driver sends only these)."""
        m = self.model
        fields = ["rot"]
        if first_stage or not m.centroids_exact:
            fields.append("x")
        if m.order == 2 and m.centroids_exact and first_stage:
            fields.append("v")
        return tuple(fields)

    def evaluate(self, stage, first_stage=False):
        """Generator: the coupling at ``stage``; yields a ``Request`` when it must be exchanged.

        ``first_stage`` marks a state on the step grid (the start of a step, or the end
        of a step whose last evaluation is the next one's first): there the centroid
        means are needed too, and a distributed ensemble may decide to stop.
        """
        if stage.coupling is not None:
            return stage.coupling
        ensemble = yield Request(stage, first_stage, self.exchange_fields(first_stage))
        stage.coupling = self.couple(ensemble, first_stage)
        return stage.coupling

    def couple(self, ensemble, first_stage=True):
        """Mean fields from full group arrays (a tuple of objects with .x, .rot, .v)."""
        m = self.model
        grp = self.group
        need_means = first_stage or not m.centroids_exact
        out = []
        for g, e in zip(m.groups, ensemble):
            if e is None or e.rot is None:
                out.append(None)
                continue
            n = grp.count(e.rot)
            s = grp.mean_field(e.rot, None if g.scales is None else _ensemble_scales(g, e, n))
            if need_means:
                out.append(GroupCoupling(s, n, _mean_rows(e.x), _mean_rows(e.v) if m.order == 2 else None))
            else:
                out.append(GroupCoupling(s, n))
        centroids = tuple(None if e is None else e.x for e in ensemble) if m.inter_group else None
        return Coupling(tuple(out), centroids)

    # -- local right-hand sides -----------------------------------------------
    def rotation_rate(self, gi, rot, coupling):
        """First order: W_i of (A-2)/(F-1).  Second order: the torque kappa/(2N)(S O^T - O S^T)[/s_i]."""
        c = coupling.groups[gi]
        scale = self._rate_scale / c.n
        rate = self.group.coupling(rot, c.s)
        inv = self._inv_scales[gi]
        if inv is not None:
            rate = self.group.algebra_scale_rows(rate, inv)
        return scale * rate

    def centroid_force(self, gi, x, coupling):
        """kappa (mean - x_i) + F-2 forces from every other group (not divided by gamma or m)."""
        m = self.model
        force = m.kappa * (coupling.groups[gi].mean_x - x)
        if m.inter_group:
            for hi, y in enumerate(coupling.centroids):
                if hi != gi and y is not None:
                    force += pair_force(x, y, m.kappa_2, m.L)
        return force

    def exact_centroids(self, gi, gs, coupling, h):
        c = coupling.groups[gi]
        return self.flows[gi].advance(gs.x, gs.v, c.mean_x, c.mean_v, h)

    def rates(self, stage, coupling):
        """Stage derivatives (k_rot, k_x, k_v, k_w) per local group; k_rot in so(d) (spatial).

        k_rot is W_i (first order) or the stage's W_i (second order); k_w = (torque - gamma W)/m.
        Centroid entries are None when centroids are solved exactly.
        """
        m = self.model
        count = self.group.count
        out = []
        for gi, gs in enumerate(stage.groups):
            if gs is None or count(gs.rot) == 0:
                out.append(None)
                continue
            rate = self.rotation_rate(gi, gs.rot, coupling)
            if m.order == 1:
                if m.centroids_exact:
                    out.append((rate, None, None, None))
                    continue
                k_rot, k_w = rate, None
            else:
                k_rot, k_w = gs.w, (rate - m.gamma * gs.w) / m.mass
            k_x = k_v = None
            if not m.centroids_exact:
                force = self.centroid_force(gi, gs.x, coupling)
                if m.order == 1:
                    k_x = force / m.gamma
                else:
                    k_x, k_v = gs.v, (force - m.gamma * gs.v) / m.mass
            out.append((k_rot, k_x, k_v, k_w))
        return out

    def in_chart(self, rates, thetas):
        """Rates in the psi-chart centred at the step start: k_rot -> dpsi^{-1}_Theta(k_rot)."""
        if thetas is None or self.group.abelian:
            return rates
        out = []
        for r, th in zip(rates, thetas):
            if r is None or th is None:
                out.append(r)
            else:
                out.append((self.group.dpsi_inv(th, r[0]),) + tuple(r[1:]))
        return out


def _mean_rows(a):
    """Mean of the rows of an (n, d) array (a BLAS product: axis-0 reductions are slow)."""
    if a is None or len(a) == 0:
        return None
    return (np.full(len(a), 1.0 / len(a)) @ a)


def _ensemble_scales(group, ensemble_rows, n):
    """Scales matching the ensemble arrays: the whole group, or ``ensemble_rows.index`` rows."""
    idx = getattr(ensemble_rows, "index", None)
    if idx is None:
        if n != group.size:
            raise ValueError(f"group {group.name!r}: ensemble has {n} rows, expected {group.size}")
        return group.scales
    return group.scales[np.asarray(idx)]


def copy_state(state):
    return State(state.t, tuple(replace(gs) for gs in state.groups))


def validate_model(model):
    if model.order not in (1, 2):
        raise SceneError(f"model.order: must be 1 or 2, got {model.order}")
    if model.order == 2 and not model.mass > 0:
        raise SceneError(f"model.mass: the second-order model needs m > 0, got {model.mass}")
    if model.order == 1 and not model.gamma > 0:
        raise SceneError(f"model.gamma: the first-order model needs gamma > 0, got {model.gamma}")
    if model.gamma < 0:
        raise SceneError(f"model.gamma: must be >= 0, got {model.gamma}")
    if not model.kappa >= 0:
        raise SceneError(f"model.kappa: must be >= 0, got {model.kappa}")
