"""Proximity graphs: agents i and k couple while their centroids are closer than a radius R.

A scene's ``graph: {radius: R}`` (``core.graph``) makes the weights of (A-1), (A-2), (F-1)
depend on the state:

    a_ik(x) = w(|xbar_i - xbar_k| / R),   w(rho) = exp(1 - 1/(1 - rho^2))  for rho < 1, else 0

w is the C-infinity bump (w(0) = 1, every derivative 0 at rho = 1), so the right-hand side is as
smooth as the model's and an integrator of order p keeps order p across the instants where a
pair enters or leaves the range.  A weight of class C^k only (e.g. (1 - rho^2)^2, C^1) would
leave a jump in the (k+1)-th derivative of the right-hand side there, and a fixed-step method
crossing it makes a local error O(h^(k+2)): global order min(p, k + 2).  ``cutoff: hard``
(w = 1 for rho < 1) makes the right-hand side itself jump, and every fixed-step method drops to
order 1 on a run where a pair crosses R (test/core/test_proximity.py measures both).

The pairs within R come from a KD-tree (``scipy.spatial.cKDTree``): O(N log N + |E|) per
evaluation, |E| the pairs in range.  An agent that evaluates only its own rows (a lockstep or
realtime process) measures its rows against every centroid it holds, O(n N).  Both decide
"in range" and weigh a pair with the same formula on the same numbers (``squared_distances``,
``bump``), so the centralised run and the distributed one agree to round-off.

Consensus under switching graphs needs the union of the graphs over time to stay connected
(Jadbabaie, Lin & Morse 2003; Moreau 2005); a proximity graph may split for good.
``components`` names the parts at one state, ``ComponentTracker`` since when they have held.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from scipy import sparse

CUTOFFS = ("smooth", "hard")
#: the KD-tree is asked for pairs within R (1 + QUERY_SLACK), and the exact test is r^2 < R^2
QUERY_SLACK = 1e-9
#: bytes per proximity weight in one centralised evaluation (pairs, distances, weights, csr)
BYTES_PER_WEIGHT = 64
#: up to this many agents the pairs come from all N (N - 1) / 2 distances and the weights are a
#: dense array (a KD-tree and a sparse matrix cost more than they save there)
SMALL = 64


def squared_distances(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """|b - a|^2 per row, summed coordinate by coordinate in order (one rounding sequence for
    every caller, whichever agent of a pair computes it: b - a = -(a - b) exactly)."""
    diff = b[..., 0] - a[..., 0]
    out = diff * diff
    for c in range(1, a.shape[-1]):
        diff = b[..., c] - a[..., c]
        out += diff * diff
    return out


def bump(r2: np.ndarray, radius: float, cutoff: str = "smooth") -> np.ndarray:
    """w(r / R) of squared distances r2: the C-infinity bump (smooth) or 1 (hard) inside R, 0
    outside."""
    s = np.asarray(r2, dtype=float) / (radius * radius)
    inside = s < 1.0
    if cutoff == "hard":
        return inside.astype(float)
    out = np.zeros_like(s)
    out[inside] = np.exp(1.0 - 1.0 / (1.0 - s[inside]))
    return out


@functools.lru_cache(maxsize=8)
def _upper(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Every pair i < k of n rows (numpy's triu_indices, kept: small ensembles ask often)."""
    return np.triu_indices(n, 1)


def pairs_within(x: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(i, k, r2) of every pair i < k of rows of x closer than ``radius``: a KD-tree,
    O(N log N + |E|) (up to ``SMALL`` rows every pair is measured)."""
    from scipy.spatial import cKDTree

    x = np.asarray(x, dtype=float)
    if len(x) <= SMALL:
        i, k = _upper(len(x))
    else:
        pairs = cKDTree(x).query_pairs(radius * (1.0 + QUERY_SLACK), output_type="ndarray")
        i, k = pairs[:, 0], pairs[:, 1]
    r2 = squared_distances(x[i], x[k])
    keep = r2 < radius * radius
    return i[keep], k[keep], r2[keep]


def weight_matrix(x: np.ndarray, radius: float, cutoff: str = "smooth",
                  rows: np.ndarray | None = None, scale: np.ndarray | None = None
                  ) -> tuple[sparse.csr_matrix | np.ndarray, sparse.csr_matrix | np.ndarray,
                             np.ndarray]:
    """(a, a diag(scale), row sums): a_ik(x) of rows ``rows`` of x (positions in x; None: every
    row) against every row of x; ``scale`` the F-1 column weights s_k (None: a itself).

    Every row of more than ``SMALL``: the KD-tree's pairs, each weighed once and set in both
    directions, a sparse matrix.  Otherwise (a few rows, or a small ensemble) the squared
    distances of the rows to every row, O(len(rows) N), a dense array.  Either way a pair is in
    range when ``squared_distances`` < R^2 and its weight is ``bump`` of that same number.
    """
    x = np.asarray(x, dtype=float)
    n = len(x)
    if rows is None and n > SMALL:
        return _sparse_weights(x, radius, cutoff, scale)
    rows = np.arange(n) if rows is None else np.asarray(rows, dtype=np.intp)
    r2 = squared_distances(x[rows][:, None, :], x[None, :, :])
    inside = r2 < radius * radius
    inside[np.arange(len(rows)), rows] = False             # an agent is not its own neighbour
    a = np.zeros(r2.shape)
    a[inside] = bump(r2[inside], radius, cutoff)
    rot = a if scale is None else a * np.asarray(scale)[None, :]
    return a, rot, a.sum(axis=1)


def _sparse_weights(x: np.ndarray, radius: float, cutoff: str,
                    scale: np.ndarray | None) -> tuple[sparse.csr_matrix, sparse.csr_matrix,
                                                       np.ndarray]:
    """``weight_matrix`` of every row of a large ensemble: the KD-tree's pairs, CSR arrays."""
    from scipy import sparse

    n = len(x)
    i, k, r2 = pairs_within(x, radius)
    w = bump(r2, radius, cutoff)
    ri, k, w = np.concatenate([i, k]), np.concatenate([k, i]), np.concatenate([w, w])
    order = np.lexsort((k, ri))                            # row-major, columns ascending
    ri, k, w = ri[order], k[order], w[order]
    indptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(ri, minlength=n), out=indptr[1:])
    a = sparse.csr_matrix((w, k, indptr), shape=(n, n))
    rot = a if scale is None else sparse.csr_matrix((w * np.asarray(scale)[k], k, indptr),
                                                    shape=(n, n))
    return a, rot, np.bincount(ri, weights=w, minlength=n).astype(float)


def components(x: np.ndarray, radius: float) -> np.ndarray:
    """Component label of every row of x in the graph of pairs closer than ``radius``."""
    from scipy import sparse
    from scipy.sparse import csgraph

    n = len(x)
    i, k, _ = pairs_within(x, radius)
    adjacency = sparse.coo_matrix((np.ones(len(i)), (i, k)), shape=(n, n))
    return csgraph.connected_components(adjacency, directed=False)[1]


def in_range(own: np.ndarray, others: np.ndarray, radius: float) -> np.ndarray:
    """Mask of the rows of ``others`` closer than ``radius`` to some row of ``own`` (a radio)."""
    if len(own) == 0 or len(others) == 0:
        return np.zeros(len(others), dtype=bool)
    r2 = squared_distances(np.asarray(own, dtype=float)[:, None, :],
                           np.asarray(others, dtype=float)[None, :, :])
    return np.any(r2 < radius * radius, axis=0)


Parts = tuple[tuple[int, ...], ...]


def parts_of(agents: Sequence[int] | np.ndarray, labels: np.ndarray) -> Parts:
    """The components as tuples of agent indices, each sorted, ordered by their first agent."""
    agents = np.asarray(agents)
    groups = [tuple(int(a) for a in agents[labels == c]) for c in np.unique(labels)]
    return tuple(sorted(groups))


def show_parts(parts: Parts, most: int = 4, members: int = 8) -> str:
    """'{0, 1, 2} {3, 4}' with at most ``most`` components of at most ``members`` agents shown."""
    def one(part: tuple[int, ...]) -> str:
        shown = ", ".join(map(str, part[:members]))
        return "{" + shown + (", ..." if len(part) > members else "") + "}"

    text = " ".join(one(p) for p in parts[:most])
    return text + (f" and {len(parts) - most} more" if len(parts) > most else "")


@dataclass(frozen=True)
class Components:
    """A group's proximity graph at time ``t``: its components (global agent indices), the time
    ``since`` from which they have been these (the first report that found them; None: not
    tracked, only this state seen), its radius."""

    group: str
    radius: float
    parts: Parts
    since: float | None
    t: float

    @property
    def split(self) -> bool:
        return len(self.parts) > 1

    def describe(self) -> str:
        """One phrase: "group 'g' split into 2 components {0, 1} {2, 3} (radius 1.5) from
        t = 2"."""
        if not self.split:
            return f"group {self.group!r} is one component (radius {self.radius:g})"
        when = (f"at t = {self.t:.6g}" if self.since is None
                else f"from t = {self.since:.6g}")
        return (f"group {self.group!r} split into {len(self.parts)} components "
                f"{show_parts(self.parts)} (radius {self.radius:g}) {when}")


@dataclass
class ComponentTracker:
    """The components of every proximity-graph group over a run's reports: the current ones,
    since when each has held, and every change (``history``)."""

    current: dict[str, Components] = field(default_factory=dict)
    history: list[Components] = field(default_factory=list)

    def update(self, t: float, group: str, radius: float, agents: Sequence[int] | np.ndarray,
               x: np.ndarray) -> Components:
        """The components of ``group`` at ``t`` from its agents' centroids ``x``."""
        parts = parts_of(agents, components(x, radius))
        last = self.current.get(group)
        since = last.since if last is not None and last.parts == parts else float(t)
        now = Components(group, radius, parts, since, float(t))
        if last is None or last.parts != parts:
            self.history.append(now)
        self.current[group] = now
        return now

    def splits(self) -> tuple[Components, ...]:
        """The groups whose proximity graph is split now."""
        return tuple(c for c in self.current.values() if c.split)

