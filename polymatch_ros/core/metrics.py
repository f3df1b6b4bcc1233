"""Diameters, energy and orthogonality defect of an ensemble (Section 2 and Theorems 4.1, 4.2).

All diameters are exact maxima over pairs, computed from centred coordinates
(so they stay accurate relative to the shape, not the coordinates) with a
pruned, blocked pairwise search: typically near-linear, O(N^2) only when no
pair can be excluded.

Per group g:
  centroid_diameter   max_{i,j} |xbar_i - xbar_j|                      (Prop. 2.1)
  rotation_diameter   max_{i,j} |O_i - O_j|_F                          (Prop. 2.2)
  matching_diameter   max_{i,j,a} |x^i_a - x^j_a| with x^i_a = xbar_i + sbar O_i r_a
                      (the paper's vertex-matching diameter; for similar ensembles each
                      polytope is compared at the group's mean scale sbar, i.e. up to its
                      own scale about its centroid, which is the matching F-1 can achieve)
  vertex_diameter     max_{i,j,a} |x^i_a - x^j_a| with the true scales s_i (equals
                      matching_diameter for congruent groups)
  energy              (m/N) sum |O_i'|_F^2 + kappa/(2N^2) sum_{i,k} |O_i - O_k|_F^2   (Prop. 2.2 i)
                      = (m/N) sum |W_i|_F^2 + (kappa/N) sum |O_i - Obar|_F^2
  orthogonality       max_i |O_i^T O_i - I|_F                          (Lemma 2.1)

Per ensemble, ``component_diameters``: for each group the matching diameter of every component
of its disconnected communication graph (``allow_disconnected: true``), None for a connected
group; None altogether when every group is connected.
"""

from dataclasses import dataclass

import numpy as np

from .model import GroupState, Model, State, System
from .so import RotationGroup

#: up to this many points the diameter compares every pair directly (measured: faster than
#: the pruned search from 4 points to 32, slower from 64 on)
DIRECT_PAIRS_UP_TO = 32


def point_set_diameter(points: np.ndarray, bound: float | None = None, block: int = 256,
                       col_block: int = 2048) -> float:
    """max_{i,j} |p_i - p_j| for points (N, k), exactly.

    Points are centred and sorted by radius r_i; a pair can only beat the best
    distance found so far if r_i + r_j exceeds it, which prunes whole blocks.
    What remains is scanned in cache-sized tiles of |p_i|^2 + |p_j|^2 - 2 p_i.p_j
    (one BLAS product each), and the winning pair's distance is recomputed directly.
    ``bound``: a known upper bound on the diameter (e.g. for rotations); the search
    stops once a pair within 1e-12 of it is found.  Up to ``DIRECT_PAIRS_UP_TO`` points every
    difference is formed directly.
    """
    p = np.asarray(points, dtype=float)
    n = p.shape[0]
    if n < 2:
        return 0.0
    q = p - p.mean(axis=0)
    if n <= DIRECT_PAIRS_UP_TO:                      # every difference at once: cheapest here
        diff = q[:, None, :] - q[None, :, :]
        return float(np.sqrt(np.einsum("ijk,ijk->ij", diff, diff).max()))
    r2 = np.einsum("ij,ij->i", q, q)
    best, pair = -1.0, (0, 0)
    i = int(np.argmax(r2))
    for _ in range(2):                               # double-normal sweeps: a good lower bound
        diff = q - q[i]
        d2 = np.einsum("ij,ij->i", diff, diff)
        j = int(np.argmax(d2))
        if d2[j] > best:
            best, pair = float(d2[j]), (i, j)
        i = j
    r = np.sqrt(r2)
    order = np.argsort(-r, kind="stable")
    rs, r2s = r[order], r2[order]
    qs = np.ascontiguousarray(q[order])
    neg = -rs
    stop = np.inf if bound is None else bound * bound * (1.0 - 1e-12)
    for a in range(0, n, block):
        lb = np.sqrt(best)
        if rs[a] + rs[0] <= lb or best >= stop:
            break                                    # no later row can reach the bound
        b = min(a + block, n)
        cols = min(b, int(np.searchsorted(neg, -(lb - rs[a]), side="left")))
        for c in range(0, cols, col_block):
            e = min(c + col_block, cols)
            d2 = qs[a:b] @ qs[c:e].T
            d2 *= -2.0
            d2 += r2s[a:b, None]
            d2 += r2s[None, c:e]
            k = int(np.argmax(d2))
            if d2.flat[k] > best:
                ii, jj = divmod(k, e - c)
                best, pair = float(d2.flat[k]), (order[a + ii], order[c + jj])
    diff = q[pair[0]] - q[pair[1]]
    return float(np.sqrt(diff @ diff))


def max_rotation_distance(d: int) -> float:
    """max |O - P|_F over SO(d): 2 sqrt(d) for even d (P = -O), 2 sqrt(d - 1) for odd d."""
    return 2.0 * np.sqrt(d if d % 2 == 0 else d - 1)


def vertices(centroids: np.ndarray, mats: np.ndarray, reference: np.ndarray,
             scales: np.ndarray | None = None) -> np.ndarray:
    """Vertices x^i_a = xbar_i + s_i O_i r_a for arrays with any leading axes.

    ``centroids`` (..., d), ``mats`` (..., d, d), ``reference`` (n_a, d) and optional
    ``scales`` (...,) give (..., n_a, d): the one vertex assembly of the package.
    """
    rotated = np.einsum("...ij,aj->...ai", np.asarray(mats), np.asarray(reference))
    if scales is not None:
        rotated = np.asarray(scales)[..., None, None] * rotated
    return np.asarray(centroids)[..., None, :] + rotated


def orthogonality(mats: np.ndarray) -> float:
    """max over all leading axes of |O^T O - I|_F: the defect Lemma 2.1 says stays zero."""
    mats = np.asarray(mats, dtype=float)
    if mats.size == 0:
        return 0.0
    gram = np.swapaxes(mats, -1, -2) @ mats
    return float(np.linalg.norm(gram - np.eye(mats.shape[-1]), axis=(-2, -1)).max())


def orthogonality_defect(grp: RotationGroup, g: np.ndarray) -> float:
    """Lemma 2.1's defect of one group's rotations in ``grp``'s representation."""
    if grp.name == "angle":           # angles are rotations by construction
        return 0.0
    return orthogonality(grp.to_matrices(g))


def rotation_energy(model: Model, gs: GroupState) -> float:
    """E of Proposition 2.2 for one group (kinetic part only for the second-order model)."""
    grp = model.rotations
    flat = grp.flat(gs.rot)
    n = flat.shape[0]
    if n == 0:
        return 0.0
    dev = flat - flat.mean(axis=0)
    potential = model.kappa * float(np.sum(dev * dev)) / n
    kinetic = 0.0
    if model.order == 2 and gs.w is not None:
        kinetic = model.mass * float(np.sum(grp.algebra_sq_norm(gs.w))) / n
    return kinetic + potential


@dataclass(frozen=True)
class GroupMetrics:
    """One group's diameters, energy and orthogonality defect (see the module docstring)."""

    centroid_diameter: float
    rotation_diameter: float
    matching_diameter: float
    vertex_diameter: float
    energy: float
    orthogonality: float


@dataclass(frozen=True)
class EnsembleMetrics:
    """Per-group metrics and the ensemble's headline diameter (max matching diameter).

    ``group_separation``: smallest distance between group centres (F-2 only, else None).
    ``component_diameters``: per group, its graph components' matching diameters (module doc).
    """

    groups: tuple[GroupMetrics, ...]
    diameter: float
    group_separation: float | None = None
    component_diameters: tuple[tuple[float, ...] | None, ...] | None = None


def _vertex_diameter(grp: RotationGroup, gs: GroupState, reference: np.ndarray,
                     scales: np.ndarray | None = None) -> float:
    """max over vertices a of the diameter of {x^i_a}_i (Theorems 4.1, 4.2)."""
    pts = vertices(gs.x, grp.to_matrices(gs.rot), reference, scales)
    return max(point_set_diameter(np.ascontiguousarray(pts[:, a])) for a in range(len(reference)))


def group_metrics(model: Model, gi: int, gs: GroupState) -> GroupMetrics:
    """Metrics of group gi; similar groups are matched at their mean scale (F-1)."""
    grp = model.rotations
    g = model.groups[gi]
    mean_scale = None if g.scales is None else float(np.mean(g.scales))
    ref = g.reference if mean_scale is None else g.reference * mean_scale
    matching = _vertex_diameter(grp, gs, ref)
    vertex = matching if g.scales is None else _vertex_diameter(grp, gs, g.reference, g.scales)
    rotation = point_set_diameter(grp.flat(gs.rot), bound=max_rotation_distance(grp.dim))
    return GroupMetrics(point_set_diameter(gs.x), rotation, matching, vertex,
                        rotation_energy(model, gs), orthogonality_defect(grp, gs.rot))


def component_diameters(model: Model, gi: int, gs: GroupState) -> tuple[float, ...] | None:
    """Matching diameter of each component of group gi's graph (None: one component); a
    proximity graph's components at this state's centroids."""
    g = model.groups[gi]
    labels = None if g.graph is None else g.graph.components_at(gs.x)
    if labels is None or labels.max(initial=0) == 0:
        return None
    grp = model.rotations
    reference = g.reference if g.scales is None else g.reference * float(np.mean(g.scales))
    parts = []
    for c in range(int(labels.max()) + 1):
        rows = np.flatnonzero(labels == c)
        part = GroupState(gs.x[rows], grp.take(gs.rot, rows))
        parts.append(_vertex_diameter(grp, part, reference))
    return tuple(parts)


def ensemble_metrics(model: Model, state: State) -> EnsembleMetrics:
    """Per-group metrics and the headline diameter (max matching diameter over groups)."""
    whole = state.all_groups()
    groups = tuple(group_metrics(model, gi, gs) for gi, gs in enumerate(whole))
    separation = None
    if model.inter_group:
        means = [gs.x.mean(axis=0) for gs in whole]
        separation = min(float(np.linalg.norm(a - b))
                         for i, a in enumerate(means) for b in means[i + 1:])
    parts = tuple(component_diameters(model, gi, gs) for gi, gs in enumerate(whole))
    components = None if all(p is None for p in parts) else parts
    return EnsembleMetrics(groups, max(m.matching_diameter for m in groups), separation,
                           components)


def stationarity(system: System, state: State) -> float:
    """max_i |W_i| of the first-order rotation field at ``state``: ~0 at any equilibrium.

    Used to tell a non-consensus equilibrium (antipodal, splay) from slow convergence.
    """
    coupling = system.couple(state.groups)
    grp = system.group
    worst = 0.0
    for gi, gs in enumerate(state.all_groups()):
        rate = system.rotation_rate(gi, gs.rot, coupling)
        if system.model.order == 2 and system.model.gamma > 0:
            rate = rate / system.model.gamma
        worst = max(worst, float(np.sqrt(np.max(grp.algebra_sq_norm(rate)))))
    return worst
