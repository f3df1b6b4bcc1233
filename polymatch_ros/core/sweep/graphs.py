"""B ensembles on communication graphs as one batch: block-diagonal weights, per-ensemble modes.

Each ensemble of a batch has its own graph (``core.graph``: the scene's ``graph`` key; a
ring or an explicit edge list is the same for all, a k-nearest graph follows each
ensemble's centroids, a random graph its own draw).  ``BatchGraphs`` stacks them:

- the coupling weights p_ik of every ensemble (``Graph.coupling_weights``, kappa/N_g
  sum_k p_ik (...) in (A-1)/(A-2) on a graph) as one block-diagonal sparse matrix of
  B*N rows, so every agent's field S_i = sum_k p_ik O_k of every ensemble is one sparse
  product per evaluation, O(|E| d^2) over the whole batch;
- the exact centroid flow of Proposition 2.1 on each ensemble's undirected graph
  (``centroids.GraphCentroidFlow``: y = V^T diag(b) x splits into modes of stiffness
  kappa lambda_j, each advanced in closed form), with the eigenmodes of each *distinct*
  graph computed once and the B small products done as one batched ``matmul``.

Directed graphs have no symmetric Laplacian: their centroids are integrated with the
rotations (``model.centroids: integrated``, as ``simulate`` does), from the same block
matrix.
"""

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # scipy is imported where it is used
    from scipy import sparse

from ..centroids import mode_propagators
from ..graph import Graph


def graph_key(graph: Graph) -> bytes:
    """Bytes that identify a graph's coupling weights (equal graphs, equal keys)."""
    w = graph.coupling_weights.tocsr()
    w.sort_indices()
    return b"|".join([w.indptr.tobytes(), w.indices.tobytes(), w.data.tobytes()])


@dataclass
class BatchGraphs:
    """The graphs of B ensembles of N agents each (module doc); ``which[e]``: e's graph."""

    graphs: list[Graph]            # the distinct graphs
    which: np.ndarray              # (B,) index into ``graphs`` per ensemble
    n: int

    @classmethod
    def of(cls, graphs: Sequence[Graph]) -> "BatchGraphs":
        """Group equal graphs (``graph_key``) so each distinct one is decomposed once."""
        keys: dict[bytes, int] = {}
        distinct: list[Graph] = []
        which = np.empty(len(graphs), dtype=int)
        for e, g in enumerate(graphs):
            k = graph_key(g)
            if k not in keys:
                keys[k] = len(distinct)
                distinct.append(g)
            which[e] = keys[k]
        return cls(distinct, which, graphs[0].size)

    def take(self, ensembles: np.ndarray) -> "BatchGraphs":
        """The graphs of some ensembles (indices into this batch), in that order."""
        return BatchGraphs(self.graphs, self.which[np.asarray(ensembles, dtype=int)], self.n)

    @property
    def directed(self) -> bool:
        return any(g.directed for g in self.graphs)

    def weights(self) -> "sparse.csr_matrix":
        """The block-diagonal (B*N, B*N) sparse matrix of every ensemble's p_ik."""
        import scipy.sparse
        blocks = [self.graphs[w].coupling_weights for w in self.which]
        return scipy.sparse.block_diag(blocks, format="csr")

    def stiffest(self) -> int:
        """The index of an ensemble whose Laplacian has the largest spectral radius."""
        rates = [g.coupling_rate() for g in self.graphs]
        return int(np.flatnonzero(self.which == int(np.argmax(rates)))[0])


class BatchGraphFlow:
    """Exact centroid flow of every ensemble on its own undirected graph (module doc).

    The same arithmetic as ``GraphCentroidFlow.advance_group`` per ensemble: x -> V
    (c * (V^T diag(b) x)) with c the modes' propagators over h.
    """

    def __init__(self, graphs: BatchGraphs, mass: float, gamma: float, kappa: float) -> None:
        self.graphs, self.mass, self.gamma, self.kappa = graphs, mass, gamma, kappa
        modes = [g.laplacian_modes for g in graphs.graphs]
        self.lam = np.array([m[0] for m in modes])                     # (U, N)
        pick = graphs.which if len(modes) > 1 else np.zeros(1, dtype=int)
        self.pick = pick                   # one shared graph: broadcast, no (B, N, N) copy
        self.synthesis = np.array([m[1] for m in modes])[pick]          # (B or 1, N, N)
        self.analysis = np.array([m[2] for m in modes])[pick]
        self._cache: dict[float, list[np.ndarray]] = {}

    def propagator(self, h: float) -> list[np.ndarray]:
        """Per ensemble and mode the coefficients over h, shaped (B or 1, N, 1)."""
        key = float(h)
        if key not in self._cache:
            if self.mass == 0.0:
                coef: tuple = (np.exp(-self.kappa * self.lam * h / self.gamma),)
            else:
                coef = mode_propagators(self.mass, self.gamma, self.kappa * self.lam, h)
            self._cache = {key: [c[self.pick][:, :, None] for c in coef]}
        return self._cache[key]

    def advance(self, x: np.ndarray, v: np.ndarray | None,
                h: float) -> tuple[np.ndarray, np.ndarray | None]:
        """(x, v) of all B*N rows after h, from their values at the step start."""
        n = self.graphs.n
        shape = x.shape
        coef = self.propagator(h)
        y = np.matmul(self.analysis, x.reshape(-1, n, shape[-1]))
        if self.mass == 0.0:
            return np.matmul(self.synthesis, coef[0] * y).reshape(shape), None
        assert v is not None, "the second-order flow carries velocities"
        w = np.matmul(self.analysis, v.reshape(-1, n, shape[-1]))
        xx, xv, vx, vv = coef
        return (np.matmul(self.synthesis, xx * y + xv * w).reshape(shape),
                np.matmul(self.synthesis, vx * y + vv * w).reshape(shape))
