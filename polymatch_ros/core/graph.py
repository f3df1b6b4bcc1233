"""Communication graphs: which agents of a group couple, with which weights a_ik.

The paper couples every pair of a group (the complete graph, kappa/N sum_k in (A-1),
(A-2)).  A graph generalises the sums to ``sum_k a_ik (...)`` with a_ik >= 0 the weight
with which agent i hears agent k (row i is the receiver):

    centroids  kappa/N_g sum_k a_ik (xbar_k - xbar_i)
    rotations  kappa/(2 N_g) sum_k a_ik (O_k O_i^T - O_i O_k^T)
             = kappa/(2 N_g) (S_i O_i^T - O_i S_i^T),
               S_i = sum_k a_ik O_k

so one sparse product ``A @ O`` gives every agent's weighted field in O(|E| d^2).  With
a_ik = 1 for all k != i this is the paper's model exactly (S_i = S - O_i and the O_i O_i^T
terms cancel), which is why the complete graph keeps the mean field and carries no matrix.

Graph specifications (a scene's ``graph`` key, overridable per group as ``groups[i].graph``):
``complete`` | ``{ring: k}`` (k neighbours on each side) | ``{k_nearest: k}`` (undirected
union of each agent's k nearest by initial centroid distance) | ``{random: {p: P, seed: S}}``
(Erdos-Renyi) | ``{edges: [[i, k], ...], weights: [...], directed: false}`` |
``{radius: R, cutoff: smooth}`` (a proximity graph: a_ik(x) = w(|xbar_i - xbar_k| / R), recomputed
at every evaluation, ``core.proximity``; ``cutoff: hard`` for w = 1 inside R).  Any mapping may
add ``normalise: degree`` (kappa/deg_i instead of kappa/N_g; default ``size``; not with a
radius) and ``allow_disconnected: true`` (accept a graph ``check_connected`` refuses, for a
radius at the initial centroids; the metrics then report each component's diameter).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import cached_property
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:  # scipy is imported where it is used: a complete-graph scene never needs it
    from scipy import sparse

from . import proximity
from .errors import SceneError
from .scenes.checks import Map, number
from .scenes.limits import MAX_LENGTH, MIN_SIZE

KINDS = ("complete", "ring", "k_nearest", "random", "edges", "radius")
NORMALISATIONS = ("size", "degree")
#: above this many agents the coupling rate is Gershgorin's bound, not the exact spectrum
DENSE_SPECTRUM_LIMIT = 1000


@dataclass(frozen=True, eq=False)
class LocalWeights:
    """A graph's weights for some rows: p (centroid sums), p diag(s) (F-1 field), row sums.

    Sparse, except a small proximity graph's (``proximity.SMALL``), which are dense arrays.
    """

    p: sparse.csr_matrix | np.ndarray
    rot: sparse.csr_matrix | np.ndarray
    row_sums: np.ndarray


@dataclass(frozen=True, eq=False)
class Graph:
    """A group's coupling graph; ``weights`` is None for the complete graph (the mean field)."""

    kind: str
    size: int
    weights: sparse.csr_matrix | None = None
    directed: bool = False
    normalise: str = "size"            # "degree": kappa/deg_i instead of kappa/N_g
    allow_disconnected: bool = False
    radius: float = 0.0                # a proximity graph's range R (kind "radius")
    cutoff: str = "smooth"             # its weight: the C-infinity bump, or "hard" (1 inside R)

    @property
    def complete(self) -> bool:
        return self.kind == "complete"

    @property
    def dynamic(self) -> bool:
        """True when the weights depend on the state (a proximity graph, ``weights_at``)."""
        return self.kind == "radius"

    def matrix(self) -> sparse.csr_matrix:
        """The weights a_ik as a sparse matrix (the complete graph's: ones off the diagonal)."""
        from scipy import sparse

        if self.dynamic:
            raise TypeError("a proximity graph's weights depend on the centroids: weights_at(x)")
        if self.weights is not None:
            return self.weights
        full = np.ones((self.size, self.size)) - np.eye(self.size)
        return sparse.csr_matrix(full)

    def in_neighbours(self, i: int) -> np.ndarray:
        """The agents (indices in the group) whose state agent ``i`` needs (on a proximity
        graph every other agent: any of them may come into range)."""
        if self.weights is None:
            return np.delete(np.arange(self.size), i)
        row = self.weights.getrow(i)
        return row.indices[row.data != 0]

    def weighted_sums(self, values: np.ndarray) -> np.ndarray:
        """sum_k a_ik values_k for every i, for values of shape (N, ...)."""
        flat = np.asarray(values, dtype=float).reshape(self.size, -1)
        if self.weights is None:
            out = flat.sum(axis=0)[None, :] - flat
        else:
            out = self.weights @ flat
        return out.reshape(np.shape(values))

    def degrees(self) -> np.ndarray:
        """sum_k a_ik for every i (the weighted in-degree)."""
        if self.weights is None:
            return np.full(self.size, self.size - 1.0)
        return np.asarray(self.weights.sum(axis=1)).ravel()


    @property
    def edge_count(self) -> int:
        """|E|: nonzero weights a_ik (an undirected edge counts twice, once per direction)."""
        return self.size * (self.size - 1) if self.weights is None else int(self.weights.nnz)

    def describe(self) -> str:
        """One phrase for ``polymatch explain``: the graph and its cost per evaluation."""
        if self.complete:
            return "complete (mean field S = sum_k O_k: O(N d^3) per evaluation, no matrix)"
        if self.dynamic:
            weight = ("C-infinity bump exp(1 - 1/(1 - (r/R)^2))" if self.cutoff == "smooth"
                      else "hard cut-off (1 inside R: fixed-step methods drop to order 1)")
            return (f"proximity, radius R = {self.radius:g}, weight {weight}, kappa/N_g; "
                    f"the pairs in range found by a KD-tree at every evaluation "
                    f"(O(N log N + |E| d^2 + N d^3))")
        kind = ("directed " if self.directed else "") + self.kind
        norm = "kappa/deg_i" if self.normalise == "degree" else "kappa/N_g"
        return (f"{kind}, |E| = {self.edge_count} weights, mean degree "
                f"{self.edge_count / max(self.size, 1):.3g}, {norm} "
                f"(one sparse product A @ O: O(|E| d^2 + N d^3) per evaluation)")

    @cached_property
    def coupling_weights(self) -> sparse.csr_matrix:
        """p_ik such that every coupling sum is kappa/N_g sum_k p_ik (...) (A-1, A-2 on a graph).

        p = a (normalise: size) or p_ik = a_ik N_g / deg_i (normalise: degree; rows of
        agents without in-neighbours stay zero).
        """
        from scipy import sparse

        a = self.matrix()
        if self.normalise != "degree":
            return a
        deg = self.degrees()
        scale = np.divide(self.size, deg, out=np.zeros_like(deg), where=deg > 0)
        return sparse.csr_matrix(sparse.diags(scale) @ a)

    @cached_property
    def components(self) -> np.ndarray:
        """Component label of every agent (weakly connected components for directed graphs)."""
        if self.dynamic:
            raise TypeError("a proximity graph's components depend on the centroids: "
                            "components_at(x)")
        if self.complete:
            return np.zeros(self.size, dtype=int)
        from scipy.sparse import csgraph

        _, labels = csgraph.connected_components(self.weights, directed=True, connection="weak")
        return labels

    def laplacian(self, scales: np.ndarray | None = None) -> sparse.csr_matrix:
        """L = (diag(r) - M) / N_g with M = diag(1/s) P diag(s) (F-1 weights; s = 1 if None).

        The centroids obey x' = -(kappa/gamma) L x (first order, scales ignored) and the
        rotations linearise at consensus to xi' = -(kappa/gamma) L xi.
        """
        from scipy import sparse

        p = self.coupling_weights
        if scales is not None:
            p = sparse.diags(1.0 / scales) @ p @ sparse.diags(scales)
        rows = np.asarray(p.sum(axis=1)).ravel()
        return sparse.csr_matrix((sparse.diags(rows) - p) / self.size)

    def coupling_rate(self, scales: np.ndarray | None = None) -> float:
        """max |lambda| of ``laplacian(scales)``: the graph's stiffness factor (1 for complete).

        Exact up to ``DENSE_SPECTRUM_LIMIT`` agents, Gershgorin's bound 2 max_i L_ii beyond.
        A proximity graph linearises at consensus, where every pair is at distance 0 with weight
        1: the complete graph's rate (1; mean s / min s with F-1 weights, as for the complete
        graph in ``stability.test_matrices``).
        """
        if self.dynamic:
            return 1.0 if scales is None else float(np.mean(scales) / np.min(scales))
        key = None if scales is None else np.asarray(scales, dtype=float).tobytes()
        cache = self.__dict__.setdefault("_rates", {})       # frozen: cached like a property
        if key not in cache:
            lap = self.laplacian(scales)
            if self.size <= DENSE_SPECTRUM_LIMIT:
                rate = np.max(np.abs(np.linalg.eigvals(lap.toarray())), initial=0.0)
            else:
                rate = 2.0 * lap.diagonal().max(initial=0.0)
            cache[key] = float(rate)
        return cache[key]

    def local_weights(self, rows: Sequence[int] | np.ndarray | None = None,
                      scales: np.ndarray | None = None) -> LocalWeights:
        """The coupling weights of some rows (None: all), for sums against the whole group."""
        from scipy import sparse

        p = self.coupling_weights
        if rows is not None:
            p = p[np.asarray(rows, dtype=int)]
        rot = p if scales is None else sparse.csr_matrix(p @ sparse.diags(scales))
        return LocalWeights(p, rot, np.asarray(p.sum(axis=1)).ravel())

    def weights_at(self, x: np.ndarray, index: np.ndarray | None = None,
                   rows: Sequence[int] | np.ndarray | None = None,
                   scales: np.ndarray | None = None) -> LocalWeights:
        """A proximity graph's weights at centroids ``x`` (the group's rows ``index``; None:
        all), for its rows ``rows`` (None: every row of x) against every row of x."""
        present = np.arange(len(x)) if index is None else np.asarray(index)
        at = None
        if rows is not None:
            at = np.searchsorted(present, np.asarray(rows, dtype=int))
            if np.any(at >= len(present)) or np.any(present[np.minimum(at, len(present) - 1)]
                                                   != np.asarray(rows)):
                raise ValueError("the ensemble lacks some of the rows to weigh")
        scale = None if scales is None else np.asarray(scales)[present]
        return LocalWeights(*proximity.weight_matrix(x, self.radius, self.cutoff, at, scale))

    def components_at(self, x: np.ndarray) -> np.ndarray:
        """Component labels at centroids ``x`` (a proximity graph's now; otherwise fixed)."""
        return proximity.components(x, self.radius) if self.dynamic else self.components

    def symmetric_pair(self) -> tuple[np.ndarray, np.ndarray]:
        """(K, b) with K symmetric, b > 0 and L = diag(b)^{-1} K (undirected graphs only).

        ``scipy.linalg.eigh(K, diag(b))`` then diagonalises L: Prop 2.1's exact flow.
        """
        a = self.matrix().toarray()
        lap_a = np.diag(a.sum(axis=1)) - a
        if self.normalise != "degree":
            return lap_a / self.size, np.ones(self.size)
        deg = self.degrees()
        return lap_a, np.where(deg > 0, deg, 1.0)

    @cached_property
    def laplacian_modes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(lambda, V, V^T diag(b)): L = V diag(lambda) V^T diag(b) for an undirected graph.

        ``scipy.linalg.eigh`` of the symmetric pair (K, diag(b)); eigenvalues below round-off
        (one per component) are exactly 0.  O(N^3) once, cached with the graph.
        """
        from scipy import linalg

        k, b = self.symmetric_pair()
        lam, vec = linalg.eigh(k) if self.normalise != "degree" else linalg.eigh(k, np.diag(b))
        lam[lam < 1e-12 * max(float(lam.max(initial=0.0)), 1.0 / self.size)] = 0.0
        return lam, vec, vec.T * b[None, :]


def build_graph(spec: Any, path: str, size: int, centroids: np.ndarray | None = None) -> Graph:
    """A validated ``Graph`` of ``size`` agents from a scene's ``graph`` value at ``path``."""
    if spec is None or spec == "complete":
        return Graph("complete", size)
    from scipy import sparse

    if isinstance(spec, str):
        raise SceneError(f"{path}: unknown graph {spec!r} (expected complete or a mapping "
                         f"with one of "
                         f"{', '.join(KINDS[1:])})")
    m = Map(spec, path, KINDS[1:] + ("weights", "directed", "normalise", "allow_disconnected",
                                      "cutoff"))
    options = _options(m)
    kinds = [k for k in KINDS[1:] if k in spec]
    if len(kinds) != 1:
        raise SceneError(f"{path}: expected exactly one of {', '.join(KINDS[1:])}")
    kind = kinds[0]
    if kind != "edges" and any(k in spec for k in ("weights", "directed")):
        raise SceneError(f"{path}: weights and directed go with edges")
    if kind != "radius" and "cutoff" in spec:
        raise SceneError(f"{m.at('cutoff')}: a cut-off goes with radius")
    if kind == "radius":
        return _radius(m, size, options)
    if kind == "ring":
        adjacency = _ring(number(spec["ring"], m.at("ring"), minimum=1, integer=True), size)
    elif kind == "k_nearest":
        k = number(spec["k_nearest"], m.at("k_nearest"), minimum=1, integer=True)
        adjacency = _k_nearest(k, size, centroids, m.at("k_nearest"))
    elif kind == "random":
        adjacency = _random(spec["random"], m.at("random"), size)
    else:
        return replace(_edges(m, size), **options)
    return Graph(kind, size, sparse.csr_matrix(adjacency), **options)


def _options(m: Map) -> dict:
    normalise = m.raw("normalise", "size")
    if normalise not in NORMALISATIONS:
        raise SceneError(f"{m.at('normalise')}: expected size or degree, got {normalise!r}")
    allow = m.raw("allow_disconnected", False)
    if not isinstance(allow, bool):
        raise SceneError(f"{m.at('allow_disconnected')}: expected true or false, got {allow!r}")
    return {"normalise": normalise, "allow_disconnected": allow}


def _radius(m: Map, size: int, options: dict) -> Graph:
    """A proximity graph ``{radius: R, cutoff: smooth | hard}`` (``core.proximity``)."""
    radius = m.number("radius", minimum=MIN_SIZE, maximum=MAX_LENGTH)
    cutoff = m.raw("cutoff", "smooth")
    if cutoff not in proximity.CUTOFFS:
        raise SceneError(f"{m.at('cutoff')}: expected smooth or hard, got {cutoff!r}")
    if options["normalise"] != "size":
        raise SceneError(f"{m.at('normalise')}: a proximity graph normalises by size: kappa/deg_i "
                         f"would jump to kappa when an agent's last neighbour leaves range")
    return Graph("radius", size, None, radius=float(radius), cutoff=cutoff, **options)


def group_graphs(scene_spec: object, group_specs: list, sizes: list[int],
                 centroids: list[np.ndarray]) -> list[Graph | None]:
    """Each group's validated graph: its own ``graph`` key or the scene's; None = complete.

    A graph on which a group cannot match as one is refused (``check_connected``; a proximity
    graph at the initial centroids) unless it says ``allow_disconnected: true``.
    """
    out = []
    for gi, (raw, size, x) in enumerate(zip(group_specs, sizes, centroids)):
        own = isinstance(raw, dict) and raw.get("graph") is not None
        path = f"groups[{gi}].graph" if own else "graph"
        graph = build_graph(raw["graph"] if own else scene_spec, path, size, x)
        if not graph.allow_disconnected:
            check_connected(graph, path if own else f"graph (groups[{gi}])", x)
        out.append(None if graph.complete else graph)
    return out


def _ring(k: int, size: int) -> np.ndarray:
    a = np.zeros((size, size))
    idx = np.arange(size)
    for step in range(1, min(k, size // 2) + 1):
        a[idx, (idx + step) % size] = 1.0
        a[idx, (idx - step) % size] = 1.0
    np.fill_diagonal(a, 0.0)
    return a


def _k_nearest(k: int, size: int, centroids: np.ndarray | None, path: str) -> np.ndarray:
    from scipy.spatial import cKDTree

    if centroids is None:
        raise SceneError(f"{path}: needs the agents' initial centroids")
    if k >= size:
        raise SceneError(f"{path}: must be < the group's {size} agents, got {k}")
    _, nearest = cKDTree(np.asarray(centroids, dtype=float)).query(centroids, k=k + 1)
    a = np.zeros((size, size))
    for i, row in enumerate(np.atleast_2d(nearest)):
        a[i, [j for j in row if j != i][:k]] = 1.0
    return np.maximum(a, a.T)                    # the undirected union


def _random(raw: object, path: str, size: int) -> np.ndarray:
    m = Map(raw, path, ("p", "seed"))
    p = m.number("p", minimum=0.0)
    if p > 1.0:
        raise SceneError(f"{m.at('p')}: must be <= 1, got {p}")
    seed = m.number("seed", 0, minimum=0, integer=True)
    upper = np.triu(np.random.default_rng(seed).random((size, size)) < p, k=1)
    return (upper | upper.T).astype(float)


def _edges(m: Map, size: int) -> Graph:
    from scipy import sparse

    raw = m.raw("edges")
    if not isinstance(raw, list) or not raw:
        raise SceneError(f"{m.at('edges')}: expected a list of [i, k] pairs")
    pairs = []
    for e, pair in enumerate(raw):
        where = f"{m.at('edges')}[{e}]"
        if not isinstance(pair, list) or len(pair) != 2:
            raise SceneError(f"{where}: expected [i, k], got {pair!r}")
        i, k = (number(v, where, minimum=0, integer=True) for v in pair)
        if i >= size or k >= size:
            raise SceneError(f"{where}: agent indices must be < the group's {size} agents")
        if i == k:
            raise SceneError(f"{where}: an agent is not its own neighbour")
        pairs.append((i, k))
    weights = m.raw("weights")
    if weights is None:
        weights = [1.0] * len(pairs)
    if not isinstance(weights, list) or len(weights) != len(pairs):
        raise SceneError(f"{m.at('weights')}: expected one positive weight per edge "
                         f"({len(pairs)})")
    w = [number(v, f"{m.at('weights')}[{j}]", positive=True) for j, v in enumerate(weights)]
    directed = m.raw("directed", False)
    if not isinstance(directed, bool):
        raise SceneError(f"{m.at('directed')}: expected true or false, got {directed!r}")
    rows, cols = zip(*pairs)
    # edge [i, k]: agent i hears agent k (and k hears i unless directed)
    a = sparse.coo_matrix((w, (rows, cols)), shape=(size, size)).toarray()
    if not directed:
        a = np.maximum(a, a.T)
    return Graph("edges", size, sparse.csr_matrix(a), directed)


def check_connected(graph: Graph, path: str, centroids: np.ndarray | None = None) -> None:
    """Refuse a graph on which the group cannot match as one.

    Undirected: one connected component.  Directed: some agent must reach all others
    along the flow of information (k -> i where a_ik > 0): exactly one strongly connected
    component of the information flow has no incoming edge.  Proximity: one component at
    the initial ``centroids`` (it may still split later: ``core.proximity``).
    """
    if graph.complete or graph.size <= 1:
        return
    from scipy.sparse import csgraph

    if graph.dynamic:
        if centroids is None:
            raise SceneError(f"{path}: a proximity graph needs the agents' initial centroids")
        labels = graph.components_at(centroids)
        count = int(labels.max(initial=0)) + 1
        if count > 1:
            raise SceneError(f"{path}: the proximity graph (radius {graph.radius:g}) is "
                             f"disconnected at the start: components {_components(labels, count)}"
                             f"; agents farther apart than the radius never hear each other "
                             f"(allow_disconnected: true runs it anyway)")
        return

    flow = graph.matrix().T.tocsr()                   # k -> i when i hears k
    if not graph.directed:
        count, labels = csgraph.connected_components(flow, directed=False)
        if count > 1:
            raise SceneError(f"{path}: the graph is disconnected: components "
                             f"{_components(labels, count)}")
        return
    count, labels = csgraph.connected_components(flow, directed=True, connection="strong")
    reached = np.zeros(count, dtype=bool)
    src, dst = flow.nonzero()
    reached[labels[dst][labels[src] != labels[dst]]] = True
    roots = np.flatnonzero(~reached)
    if len(roots) > 1:
        groups = "; ".join(_members(labels, r) for r in roots)
        raise SceneError(f"{path}: no agent reaches all others along the directed edges "
                         f"(independent sources: {groups})")


def _members(labels: np.ndarray, component: int | np.integer) -> str:
    members = np.flatnonzero(labels == component)
    shown = ", ".join(map(str, members[:8])) + (", ..." if len(members) > 8 else "")
    return "{" + shown + "}"


def _components(labels: np.ndarray, count: int) -> str:
    parts = [_members(labels, c) for c in range(min(count, 4))]
    return " ".join(parts) + (f" and {count - 4} more" if count > 4 else "")
