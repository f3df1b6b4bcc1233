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

On a communication graph (``Group.graph``, ``core.graph``) every sum over k becomes
sum_k a_ik (...): S_i = sum_k a_ik s_k O_k is one field per agent (one sparse product
A @ O, O(|E| d^2)) and the centroid force kappa/N sum_k a_ik (xbar_k - xbar_i).  With
a_ik = 1 for every pair this is the paper's model; the complete graph keeps the mean field.
On a proximity graph (``core.proximity``) a_ik = w(|xbar_i - xbar_k| / R) is weighed anew at
every evaluation from the centroids of the ensemble it is given (``Graph.weights_at``), for
the first- and the second-order model alike: the weights enter only these two sums.

``lohe_torque`` is the one assembly of the rotation coupling (A-1)/(A-2)/(F-1).
Centroids never couple to rotations, so centroid and rotation parts are
evaluated separately (``centroids``: the exact flow of Proposition 2.1 and the
F-2 force).

Every quantity an agent needs from the others is collected by ``System.couple``
from an *ensemble* (full group arrays in agent-index order).  The centralised
simulator passes its own arrays; a ROS agent passes the arrays it assembled
from its peers' messages.  Both then run the same code.
"""

from collections.abc import Callable, Generator, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any, TypeGuard

import numpy as np

from .centroids import CentroidFlow, GraphCentroidFlow, pair_force
from .errors import SceneError
from .graph import Graph
from .so import RotationGroup
from .so.base import Array, MeanField, constant_weights

__all__ = ["Coupling", "CentroidFlow", "Group", "GroupCoupling", "GroupState", "Model", "Request",
           "State", "System", "lohe_torque", "pair_force", "validate_model"]


@dataclass(frozen=True)
class Group:
    """One congruent (or similar) sub-ensemble sharing a reference shape."""

    name: str
    size: int                      # N_g
    reference: np.ndarray          # (n, d) centred r_a
    edges: tuple
    scales: np.ndarray | None = None   # (N_g,) s_i for similar ensembles (F-1); None = congruent
    start: int = 0                 # global index of the group's first agent
    graph: Graph | None = None     # communication graph; None: complete (the paper's mean field)

    @property
    def indices(self) -> range:
        return range(self.start, self.start + self.size)


@dataclass(frozen=True)
class Model:
    """Model parameters and structure; what the scene requires and nothing more."""

    dim: int
    order: int                     # 1, 2
    kappa: float
    gamma: float
    mass: float
    groups: tuple[Group, ...]
    rotations: RotationGroup
    kappa_2: float = 0.0
    L: float = 0.0
    #: "exact": decoupled centroids follow Proposition 2.1's closed form; "integrated": the
    #: integrator's stages carry them (the full model, kept to show the reduction is exact)
    centroids: str = "exact"

    @property
    def n_agents(self) -> int:
        return sum(g.size for g in self.groups)

    @cached_property
    def inter_group(self) -> bool:
        """True when the F-2 inter-group potential is active."""
        return self.kappa_2 != 0.0 and len(self.groups) > 1

    @cached_property
    def centroids_exact(self) -> bool:
        """Centroids decouple into linear symmetric consensus per group: solved in closed form.

        Directed graphs (non-symmetric Laplacian) integrate them with the method's stages, and
        so do proximity graphs (weights that depend on the centroids: a nonlinear consensus).
        """
        directed = any(g.graph is not None and (g.graph.directed or g.graph.dynamic)
                       for g in self.groups)
        return not self.inter_group and self.centroids == "exact" and not directed

    def group_of(self, agent: int) -> tuple[int, int]:
        for gi, g in enumerate(self.groups):
            if g.start <= agent < g.start + g.size:
                return gi, agent - g.start
        raise IndexError(f"agent {agent} is not in the scene (0..{self.n_agents - 1})")


@dataclass(slots=True)
class GroupState:
    """Rows of one group: centroid offsets x (n, d), rotations, and velocities (second order)."""

    x: np.ndarray
    rot: Array
    v: np.ndarray | None = None
    w: Array | None = None


@dataclass(slots=True)
class State:
    """An ensemble (or an agent's local rows of it) at time t.

    ``coupling`` caches the mean field evaluated at exactly this state, so a
    method whose last stage is the next step's first (FSAL) does not exchange twice.
    """

    t: float
    groups: tuple[GroupState | None, ...]
    coupling: "Coupling | None" = field(default=None, repr=False)

    def all_groups(self) -> tuple[GroupState, ...]:
        """``groups`` of a whole ensemble, where every group has its rows (centralised runs)."""
        present = tuple(gs for gs in self.groups if gs is not None)
        if len(present) != len(self.groups):
            raise ValueError("the state lacks the rows of a group")
        return present


@dataclass(slots=True)
class Request:
    """A stage whose mean field is needed: the driver answers with the ensemble's arrays."""

    stage: State
    boundary: bool
    fields: tuple[str, ...]


@dataclass(slots=True)
class GroupCoupling:
    """What agent i needs from its group: S, N, and the centroid mean (and mean velocity).

    On a graph ``s`` holds one field S_i per local row and the centroids come as
    ``neighbour_x`` = sum_k p_ik x_k per local row (integrated) or as the group's arrays at
    the step start (``group_x``, ``group_v``, rows ``index``: the exact flow).
    """

    s: MeanField
    n: int
    mean_x: np.ndarray | None = None
    mean_v: np.ndarray | None = None
    neighbour_x: np.ndarray | None = None
    group_x: np.ndarray | None = None
    group_v: np.ndarray | None = None
    index: np.ndarray | None = None
    row_sums: np.ndarray | None = None     # sum_k p_ik per local row (graphs)


@dataclass(slots=True)
class Coupling:
    """The mean field of every group at one stage (``System.couple``)."""

    groups: tuple[GroupCoupling | None, ...]
    centroids: tuple | None = None     # every group's full centroid array (F-2 only)


def lohe_torque(group: RotationGroup, rot: Array, coupling: GroupCoupling, gain: float,
                inv_scales: np.ndarray | None = None) -> Array:
    """gain/(2N) (S O_i^T - O_i S^T) [/ s_i] for every rotation: the package's one Lohe torque.

    With gain = kappa it is the torque of the second-order model (A-1); with
    gain = kappa/gamma it is W_i of the first-order model (A-2).  S is the group's mean
    field (sum_k s_k O_k under F-1) and ``inv_scales`` the local 1/s_i (F-1 weights).
    """
    rate = group.coupling(rot, coupling.s)            # a new array: scaled in place
    if inv_scales is not None:
        rate = group.algebra_scale_rows(rate, inv_scales)
    rate *= gain / 2.0 / coupling.n
    return rate


class System:
    """The model evaluated for a set of local rows against an ensemble.

    ``rows[g]`` are the local rows of group g (indices inside the group);
    ``None`` means all rows (the centralised simulator).
    """

    def __init__(self, model: Model, rows: Sequence | None = None) -> None:
        self.model = model
        self.group = model.rotations
        self.rows = tuple(None for _ in model.groups) if rows is None else tuple(rows)
        # fixed graphs' weights once; a proximity graph's at every evaluation (``_couple_graph``)
        self.graph_weights = tuple(
            None if g.graph is None or g.graph.dynamic else g.graph.local_weights(r, g.scales)
            for g, r in zip(model.groups, self.rows))
        self.flows = tuple(
            GraphCentroidFlow(model.mass, model.gamma, model.kappa, g.graph, r)
            if g.graph is not None and model.centroids_exact
            else CentroidFlow(model.mass, model.gamma, model.kappa)
            for g, r in zip(model.groups, self.rows))
        # the torque's gain: kappa or kappa/gamma (A-2, where W_i itself is the torque)
        self._torque_gain = model.kappa if model.order == 2 else model.kappa / model.gamma
        self._inv_scales: list[np.ndarray | None] = []
        for g, r in zip(model.groups, self.rows):
            if g.scales is None:
                self._inv_scales.append(None)
            else:
                s = g.scales if r is None else g.scales[np.asarray(r)]
                self._inv_scales.append(1.0 / s)

    # -- what must be exchanged ---------------------------------------------
    def exchange_fields(self, first_stage: bool) -> tuple[str, ...]:
        """Fields of a stage that other agents need (the distributed driver sends only these)."""
        m = self.model
        fields = ["rot"]
        if first_stage or not m.centroids_exact:
            fields.append("x")
        if m.order == 2 and m.centroids_exact and first_stage:
            fields.append("v")
        return tuple(fields)

    def sources(self, gi: int, row: int, first_stage: bool) -> dict[str, np.ndarray]:
        """The rows of group gi whose fields agent ``row`` of it needs at a stage.

        Complete graph: every other row.  On a graph the rotations (and integrated
        centroids) come from the in-neighbours only; the exact centroid flow of an
        undirected graph is a global linear map, so at a step's first stage it reads the
        whole group (``model.centroids: integrated`` keeps every exchange between
        in-neighbours).  On a proximity graph every other row, for every field: any agent
        may come into range.
        """
        g, m = self.model.groups[gi], self.model
        everyone = np.delete(np.arange(g.size), row)
        near = everyone if g.graph is None else g.graph.in_neighbours(row)
        fields = self.exchange_fields(first_stage)
        cent = near                              # complete graph: near is everyone
        if m.centroids_exact and g.graph is not None:
            cent = everyone if first_stage else near[:0]
        return {f: near if f == "rot" else cent for f in fields}

    def evaluate(self, stage: State,
                 first_stage: bool = False) -> Generator[Request, Any, Coupling]:
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

    def couple(self, ensemble: Sequence, first_stage: bool = True) -> Coupling:
        """Mean fields from full group arrays (a tuple of objects with .x, .rot, .v)."""
        m = self.model
        grp = self.group
        need_means = first_stage or not m.centroids_exact
        out: list[GroupCoupling | None] = []
        for gi, (g, e) in enumerate(zip(m.groups, ensemble)):
            if e is None or e.rot is None:
                out.append(None)
                continue
            if g.graph is not None:
                out.append(self._couple_graph(gi, e, need_means))
                continue
            n = grp.count(e.rot)
            s = grp.mean_field(e.rot, None if g.scales is None else _ensemble_scales(g, e, n))
            if need_means:
                mean_v = _mean_rows(e.v) if m.order == 2 else None
                out.append(GroupCoupling(s, n, _mean_rows(e.x), mean_v))
            else:
                out.append(GroupCoupling(s, n))
        centroids = tuple(None if e is None else e.x for e in ensemble) if m.inter_group else None
        return Coupling(tuple(out), centroids)

    def _couple_graph(self, gi: int, e: Any, need_means: bool) -> GroupCoupling:
        """Per-row fields S_i = sum_k a_ik s_k O_k (one sparse product) and centroid sums.

        A proximity graph's weights come from the ensemble's centroids ``e.x`` (``weights_at``).
        """
        g = self.model.groups[gi]
        idx = getattr(e, "index", None)
        fixed = self.graph_weights[gi]
        if g.graph is not None and g.graph.dynamic:
            w = g.graph.weights_at(e.x, idx, self.rows[gi], g.scales)
            p, rot = w.p, w.rot
        else:
            assert fixed is not None, "a graph group has weights"
            w = fixed
            p, rot = (w.p, w.rot) if idx is None else (w.p[:, idx], w.rot[:, idx])
        out = GroupCoupling(self.group.neighbour_fields(e.rot, rot), g.size, row_sums=w.row_sums)
        if not self.model.centroids_exact:
            out.neighbour_x = p @ e.x
        elif need_means:
            out.group_x, out.index = e.x, idx
            out.group_v = e.v if self.model.order == 2 else None
        return out

    # -- local right-hand sides -----------------------------------------------
    def rotation_rate(self, gi: int, rot: Array, coupling: Coupling) -> Array:
        """First order: W_i of (A-2)/(F-1).  Second order: the torque of (A-1)/(F-1).

        Both are ``lohe_torque`` with the model's gain (kappa/gamma or kappa).
        """
        c = coupling.groups[gi]
        assert c is not None, f"no coupling for group {gi}"
        return lohe_torque(self.group, rot, c, self._torque_gain,
                           self._inv_scales[gi])

    def centroid_force(self, gi: int, x: np.ndarray, coupling: Coupling) -> np.ndarray:
        """kappa (mean - x_i) + F-2 forces from every other group (not divided by gamma or m).

        On a graph: kappa/N sum_k p_ik (x_k - x_i) = kappa/N (neighbour_x - r_i x_i).
        """
        m = self.model
        c = coupling.groups[gi]
        assert c is not None, f"no coupling for group {gi}"
        if c.neighbour_x is not None:
            assert c.row_sums is not None, "a graph's coupling carries its row sums"
            force = (m.kappa / c.n) * (c.neighbour_x - c.row_sums[:, None] * x)
        else:
            assert c.mean_x is not None, "the coupling carries the centroid mean"
            force = m.kappa * (c.mean_x - x)
        if m.inter_group:
            assert coupling.centroids is not None, "F-2 couples every group's centroids"
            for hi, y in enumerate(coupling.centroids):
                if hi != gi and y is not None:
                    force += pair_force(x, y, m.kappa_2, m.L)
        return force

    def exact_centroids(self, gi: int, gs: GroupState, coupling: Coupling,
                        h: float) -> tuple[np.ndarray, np.ndarray | None]:
        """(x, v) of group gi after h on the exact flow of Proposition 2.1 (or its graph form)."""
        c = coupling.groups[gi]
        assert c is not None, f"no coupling for group {gi}"
        flow = self.flows[gi]
        if c.group_x is not None:
            assert isinstance(flow, GraphCentroidFlow)
            return flow.advance_group(c.group_x, c.group_v, h, c.index)
        assert isinstance(flow, CentroidFlow) and c.mean_x is not None
        return flow.advance(gs.x, gs.v, c.mean_x, c.mean_v, h)

    def is_active(self, gs: GroupState | None) -> TypeGuard[GroupState]:
        """True when the group has local rows to advance (an agent holds rows of some groups)."""
        return gs is not None and self.group.count(gs.rot) > 0

    def per_active_group(self, groups: Sequence[GroupState | None],
                         fn: Callable[[int, GroupState], Any]) -> list:
        """[fn(gi, gs) per group], None for a group without local rows (``is_active``)."""
        return [fn(gi, gs) if self.is_active(gs) else None for gi, gs in enumerate(groups)]

    def rates(self, stage: State, coupling: Coupling) -> list[tuple | None]:
        """Stage derivatives (k_rot, k_x, k_v, k_w) per local group; k_rot in so(d) (spatial).

        k_rot is W_i (first order) or the stage's W_i (second order); k_w = (torque - gamma W)/m.
        Centroid entries are None when centroids are solved exactly.
        """
        m = self.model

        def group_rates(gi, gs):
            rate = self.rotation_rate(gi, gs.rot, coupling)
            if m.order == 1:
                if m.centroids_exact:
                    return rate, None, None, None
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
            return k_rot, k_x, k_v, k_w
        return self.per_active_group(stage.groups, group_rates)

    def in_chart(self, rates: list, thetas: Sequence | None) -> list:
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
    return constant_weights(len(a), 1.0 / len(a)) @ a


def _ensemble_scales(group, ensemble_rows, n):
    """Scales matching the ensemble arrays: the whole group, or ``ensemble_rows.index`` rows."""
    idx = getattr(ensemble_rows, "index", None)
    if idx is None:
        if n != group.size:
            raise ValueError(f"group {group.name!r}: ensemble has {n} rows, expected {group.size}")
        return group.scales
    return group.scales[np.asarray(idx)]


def validate_model(model: Model) -> None:
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
