"""Many independent ensembles integrated as one: a batch axis over the rows of one group.

B ensembles of the same single-group model (same d, N, reference shape, kappa, gamma, m)
are stacked into one group of B*N rows.  ``BatchSystem`` is the core's ``System`` with one
change: every sum over k of (A-1)/(A-2) runs over the agent's own ensemble only,

    S_i = sum_{k in ens(i)} O_k,    mean_i = (1/N) sum_{k in ens(i)} xbar_k,

i.e. one sparse product with the block-diagonal matrix kron(I_B, 1 1^T) (the rotation
group's ``neighbour_fields``, the path of communication graphs).  On a communication graph
the block-diagonal matrix holds each ensemble's weights p_ik instead (``graphs``), so
S_i = sum_k p_ik O_k over the agent's own ensemble's graph, still one sparse product.
Torque, centroid force, the exact centroid flow of Proposition 2.1 and every stepper are
the core's own, so a batched run equals B separate ``simulate`` runs to round-off.  The
sums are taken once per ensemble (a (B, B*N) sparse product with B*N entries) and handed
to each row of it.

Angles (d = 2) take cos and sin from one tangent of the half angle (``HalfAngles``):
t = tan(theta/2), cos = (1 - t^2)/(1 + t^2), sin = 2t/(1 + t^2): one transcendental per
row and stage instead of two (and numpy's float64 tangent may use SIMD kernels where its
cosine and sine do not).  They agree with np.cos/np.sin to 1 ulp (``test_sweep``), so the
batch still equals separate runs to round-off.

``BatchMetrics`` are the core's metrics (matching, rotation and centroid diameters of
``core.metrics``; the stationarity |W_i| of ``metrics.stationarity``) per ensemble.
"""

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..graph import LocalWeights
from ..model import Coupling, GroupCoupling, GroupState, Model, State, System
from ..so.base import Array, RotationGroup
from ..so.so2 import SO2
from .graphs import BatchGraphFlow, BatchGraphs


class HalfAngles(SO2):
    """SO(2) as angles with cos and sin of one array from tan(theta/2) (module doc)."""

    def _cos_sin(self, g):
        if self._trig[0] is not g:
            t = np.tan(0.5 * g)
            inv = 1.0 / (1.0 + t * t)
            self._trig = (g, (1.0 - t * t) * inv, (2.0 * inv) * t)
        return self._trig[1], self._trig[2]

    def to_matrices(self, g: Array) -> np.ndarray:
        c, s = self._cos_sin(g)
        return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)

    def flat(self, g: Array) -> np.ndarray:
        c, s = self._cos_sin(g)
        return np.stack([c, -s, s, c]).T           # (N, 4) rows, columns contiguous


def batch_rotations(rotations: RotationGroup) -> RotationGroup:
    """The representation a batch computes with: ``HalfAngles`` for angles, else the same."""
    return HalfAngles() if type(rotations) is SO2 else rotations


class BatchSystem(System):
    """``System`` for ``ensembles`` stacked copies of one single-group model (module doc).

    On a communication graph (``graphs``: every ensemble's, ``core.sweep.graphs``) each
    row's field is S_i = sum_k p_ik O_k over its own ensemble's graph, one sparse product
    with the block-diagonal weights; the centroids follow each graph's exact flow
    (undirected) or are integrated from the same weights (directed), as in ``simulate``.
    """

    def __init__(self, model: Model, ensembles: int, graphs: BatchGraphs | None = None) -> None:
        group = model.groups[0]
        if len(model.groups) != 1 or group.scales is not None \
                or (group.graph is None) != (graphs is None):
            raise ValueError("a batch stacks congruent single-group ensembles (with their "
                             "graphs when the model has one)")
        self.n, self.ensembles = group.size, int(ensembles)
        stacked = replace(model, groups=(replace(group, size=self.n * self.ensembles,
                                                 graph=None),),
                          centroids="exact" if model.centroids_exact else "integrated")
        super().__init__(replace(stacked, rotations=batch_rotations(model.rotations)))
        self.template = model
        import scipy.sparse  # here: a command refusing its arguments never needs it
        eye = scipy.sparse.identity(self.ensembles, format="csr")
        self.sums = scipy.sparse.kron(eye, np.ones((1, self.n)), format="csr")
        self.means = self.sums / self.n
        self.owner = np.repeat(np.arange(self.ensembles), self.n)     # row -> its ensemble
        self.graphs = graphs
        self.graph_flow: BatchGraphFlow | None = None
        if graphs is not None:
            w = graphs.weights()
            self.graph_weights = (LocalWeights(w, w, np.asarray(w.sum(axis=1)).ravel()),)
            if model.centroids_exact:
                self.graph_flow = BatchGraphFlow(graphs, model.mass, model.gamma, model.kappa)

    def couple(self, ensemble: Sequence, first_stage: bool = True) -> Coupling:
        """Per-row mean fields S_i and centroid means of each row's own ensemble."""
        (e,) = ensemble
        need_means = first_stage or not self.model.centroids_exact
        if self.graphs is not None:
            return Coupling((self._couple_graph_rows(e, need_means),))
        s = self.group.take(self.group.neighbour_fields(e.rot, self.sums), self.owner)
        if not need_means:
            return Coupling((GroupCoupling(s, self.n),))
        mean_v = (self.means @ e.v)[self.owner] if self.model.order == 2 else None
        return Coupling((GroupCoupling(s, self.n, (self.means @ e.x)[self.owner], mean_v),))

    def _couple_graph_rows(self, e: Any, need_means: bool) -> GroupCoupling:
        """S_i = sum_k p_ik O_k (one block-diagonal product) and the centroid inputs."""
        w = self.graph_weights[0]
        assert w is not None, "a graph batch has weights"
        out = GroupCoupling(self.group.neighbour_fields(e.rot, w.rot), self.n, row_sums=w.row_sums)
        if not self.model.centroids_exact:
            out.neighbour_x = w.p @ e.x
        elif need_means:
            out.group_x, out.group_v = e.x, (e.v if self.model.order == 2 else None)
        return out

    def exact_centroids(self, gi: int, gs: GroupState, coupling: Coupling,
                        h: float) -> tuple[np.ndarray, np.ndarray | None]:
        """Prop 2.1's flow: the mean-field form, or each ensemble's graph modes."""
        if self.graph_flow is None:
            return super().exact_centroids(gi, gs, coupling, h)
        c = coupling.groups[gi]
        assert c is not None and c.group_x is not None, "graph centroids read the group"
        return self.graph_flow.advance(c.group_x, c.group_v, h)

    def row_rates(self, state: State) -> np.ndarray:
        """|W_i| of the first-order field (|torque|/gamma for (A-1)) per row (``stationarity``)."""
        gs = state.all_groups()[0]
        rate = self.rotation_rate(0, gs.rot, self.couple(state.groups))
        if self.model.order == 2 and self.model.gamma > 0:
            rate = rate / self.model.gamma
        return np.sqrt(self.group.algebra_sq_norm(rate))


def stack_states(rotations: RotationGroup, states: Sequence[State]) -> State:
    """One state of B*N rows from B single-group states (in order)."""
    parts = [st.all_groups()[0] for st in states]
    v = None if parts[0].v is None else np.concatenate([p.v for p in parts])
    ws: list[Any] = [p.w for p in parts]               # all None or all arrays (one model)
    w = None if parts[0].w is None else rotations.algebra_concat(ws)
    return State(states[0].t, (GroupState(np.concatenate([p.x for p in parts]),
                                          rotations.concat([p.rot for p in parts]), v, w),))


def ensemble_rows(ensembles: np.ndarray, n: int) -> np.ndarray:
    """Row indices of the given ensembles (each N consecutive rows)."""
    return (np.asarray(ensembles)[:, None] * n + np.arange(n)).ravel()


def take_ensembles(rotations: RotationGroup, state: State, ensembles: np.ndarray, n: int) -> State:
    """The rows of some ensembles of a stacked state (no cached coupling)."""
    rows = ensemble_rows(ensembles, n)
    gs = state.all_groups()[0]
    return State(state.t, (GroupState(gs.x[rows], rotations.take(gs.rot, rows),
                                      None if gs.v is None else gs.v[rows],
                                      None if gs.w is None else
                                      rotations.algebra_take(gs.w, rows)),))


def ensembles_last(values: np.ndarray, n: int) -> np.ndarray:
    """Per-row columns (..., B*N) as (..., N, B): agent j of ensemble e at [..., j, e] (a copy)."""
    shape = values.shape[:-1]
    return np.ascontiguousarray(np.swapaxes(values.reshape(shape + (-1, n)), -1, -2))


def pair_diameters(points: np.ndarray) -> np.ndarray:
    """max_{i<j} |p_i - p_j| per ensemble of points laid out (..., k, N, B), exactly.

    k indexes the coordinates; leading axes (e.g. the vertices a of x^i_a) are maxima too:
    max_{a, i<j} |p_ia - p_ja|.  The pairs (i, i + lag) of every ensemble are one array
    difference per lag along the ensembles (the contiguous axis): no pair index arrays.
    """
    n, b = points.shape[-2:]
    rows = points.reshape((-1,) + points.shape[-3:])
    out = np.zeros(b)
    for lag in range(1, n):
        diff = rows[:, :, lag:] - rows[:, :, :-lag]          # (middle, k, N - lag, B)
        diff *= diff
        np.maximum(out, diff.sum(axis=1).max(axis=(0, 1)), out=out)
    return np.sqrt(out)


@dataclass(frozen=True)
class BatchMetrics:
    """Per ensemble (arrays of length B) the core's diameters and the rotation field's size."""

    matching: np.ndarray
    rotation: np.ndarray | None = None
    centroid: np.ndarray | None = None


def batch_metrics(model: Model, state: State, matching_only: bool = False) -> BatchMetrics:
    """Matching (Thm 4.1/4.2), rotation (Prop 2.2) and centroid (Prop 2.1) diameters.

    ``model`` is one ensemble's (single-group) model; ``state`` stacks any number of them.
    """
    n, d = model.groups[0].size, model.dim
    gs = state.all_groups()[0]
    grp, ref = batch_rotations(model.rotations), model.groups[0].reference
    entries = ensembles_last(grp.flat(gs.rot).T, n)         # O_i[r, c] at [r d + c, j, e]
    x = ensembles_last(gs.x.T, n)                            # (d, N, B)
    # x^i_a = xbar_i + O_i r_a, as ``metrics.vertices``: one (n_a d, d d) x (d d, B N) product
    spread = np.einsum("ac,rs->arsc", ref, np.eye(d)).reshape(len(ref) * d, d * d)
    verts = (spread @ entries.reshape(d * d, -1)).reshape((len(ref),) + x.shape)
    verts += x                                    # in place: no second array of that size
    matching = pair_diameters(verts)
    if matching_only:
        return BatchMetrics(matching)
    return BatchMetrics(matching, pair_diameters(entries), pair_diameters(x))


@dataclass(frozen=True)
class Equilibrium:
    """What the end state of non-matching ensembles looks like (per ensemble, length B).

    ``stationarity``  max_i |W_i| of the first-order field (``metrics.stationarity``);
                      for (A-1) also the angular velocities max_i |W_i| themselves
    ``order_parameter`` |(1/N) sum_k O_k|_F / sqrt(d): 1 at consensus, 0 when S = 0
    ``asymmetry``     max_{i,j} |O_i^T O_j - O_j^T O_i|_F: 0 when every pair is at consensus
                      or a half-turn apart (an antipodal configuration)
    """

    stationarity: np.ndarray
    order_parameter: np.ndarray
    asymmetry: np.ndarray


def stationarity(system: BatchSystem, state: State) -> np.ndarray:
    """max_i |W_i| per ensemble: the first-order field and (second order) the velocities."""
    gs = state.all_groups()[0]
    still = system.row_rates(state)
    if gs.w is not None:
        still = np.maximum(still, np.sqrt(system.group.algebra_sq_norm(gs.w)))
    return still.reshape(-1, system.n).max(axis=1)


def equilibrium_measures(system: BatchSystem, state: State) -> Equilibrium:
    """Stationarity, order parameter and pairwise asymmetry of every ensemble of ``state``."""
    n, d = system.n, system.model.dim
    gs = state.all_groups()[0]
    b = len(gs.x) // n
    grp = system.group
    still = stationarity(system, state)
    mats = grp.to_matrices(gs.rot).reshape(b, n, d, d)
    order = np.linalg.norm(mats.mean(axis=1), axis=(1, 2)) / np.sqrt(d)
    rel = np.einsum("bkji,bljm->bklim", mats, mats)
    asym = np.linalg.norm(rel - np.swapaxes(rel, -1, -2), axis=(-2, -1)).max(axis=(1, 2))
    return Equilibrium(still, order, asym)
