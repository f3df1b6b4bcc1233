"""Recover (centroid, rotation, scale) of vertex sets against a reference shape.

Section 3 of the paper writes a rigidly moving polytope as

    x^i_a = xbar^i + s^i O^i r_a,      O^i in SO(d),

with xbar^i the vertex mean and r_a the centred reference (s^i = 1 for
congruent ensembles, Section 4.1.1 for similar ones).  Given the vertices
we find xbar^i as the mean and (O^i, s^i) by the Kabsch/Umeyama SVD
solution, and check the residual against a tolerance relative to the
polytope's size.

When span{r_a} has dimension k <= d - 2 the rotation is not unique
(Lemma 3.2 assumes k = d); we then take the rotation of least angle
(largest trace) among all that fit.  For k = d - 1 (a triangle in R^3)
the rotation is still unique: det O = +1 fixes the normal direction.
"""

import warnings
from typing import Any

import numpy as np

from ..errors import ShapeError
from .shapes import check_distinct_vertices


class RotationNotUniqueWarning(UserWarning):
    """The reference spans fewer than d - 1 dimensions; least-angle rotation taken."""


def _complete(p, vk):
    """The rotation O with O vk = p (d x k orthonormal each) of least angle, det O = +1.

    On the complement, maximise tr(O) = const + tr(T Vp^T Up) over T in O(d - k) with the
    determinant that makes det O = +1 (an orthogonal Procrustes problem).
    """
    d, k = p.shape
    up = np.linalg.qr(p, mode="complete")[0][:, k:]
    vp = np.linalg.qr(vk, mode="complete")[0][:, k:]
    sign = np.linalg.det(np.hstack([p, up])) * np.linalg.det(np.hstack([vk, vp]))
    pp, _, qt = np.linalg.svd(vp.T @ up)
    corr = np.ones(d - k)
    corr[-1] = sign * np.linalg.det(pp) * np.linalg.det(qt)
    return p @ vk.T + up @ ((qt.T * corr) @ pp.T) @ vp.T


def _least_angle_rotation(m, rank):
    """Kabsch: argmax tr(O^T m) over SO(d), m = q^T r; for rank <= d - 2 the least-angle one.

    For rank >= d - 1 this is the usual U diag(1, .., det) V^T.
    """
    u, _, vt = np.linalg.svd(m)
    d = m.shape[0]
    if rank >= d - 1:
        corr = np.ones(d)
        corr[-1] = np.linalg.det(u) * np.linalg.det(vt)
        return (u * corr) @ vt
    return _complete(u[:, :rank], vt[:rank].T)


def _rotation_from_reference_svd(q, ref_u, ref_s, ref_vt, rank):
    """For an ill-conditioned reference (a nearly collinear triangle): map its singular directions.

    Kabsch works with q^T r and squares the reference's condition number; here
    O v_j = q^T u_j / s_j for the j-th singular triple of r, orthonormalised in order of
    decreasing s_j, then completed with det +1.  The roll about a nearly degenerate axis is
    then as accurate as the data allow.
    """
    d = ref_vt.shape[0]
    images: list[np.ndarray] = []
    for j in range(min(rank, d - 1)):
        c = q.T @ ref_u[:, j] / ref_s[j]
        for img in images:
            c = c - (img @ c) * img
        images.append(c / np.linalg.norm(c))
    return _complete(np.array(images).T, ref_vt[:len(images)].T)


def _checked_vertex_sets(vertex_sets, n, d, label, offset):
    """Each polytope's vertices as a finite (n, d) array with distinct vertices, or ShapeError."""
    sets = []
    for i, raw in enumerate(vertex_sets):
        name = f"{label} {i + offset}"
        try:
            v = np.array(raw, dtype=float)
        except (TypeError, ValueError):
            raise ShapeError(f"{name}: vertices are not a list of coordinate lists") from None
        if v.ndim != 2:
            raise ShapeError(f"{name}: vertices are not a list of coordinate lists")
        if v.shape[1] != d:
            raise ShapeError(f"{name}: vertices have {v.shape[1]} coordinates, "
                             f"the scene has dimension {d}")
        if v.shape[0] != n:
            raise ShapeError(f"{name} has {v.shape[0]} vertices, the reference has {n}")
        bad = np.argwhere(~np.isfinite(v))
        if bad.size:
            raise ShapeError(f"{name}: vertex {bad[0][0]} has a non-finite coordinate "
                             f"({v[tuple(bad[0])]})")
        check_distinct_vertices(v, name, ShapeError)
        sets.append(v)
    return sets


def decompose(vertex_sets: Any, reference: Any, *, similar: bool = False, tol: float = 1e-9,
              label: str = "polytope",
              offset: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centroids (N, d), rotations (N, d, d) and scales (N,) of congruent or similar vertex sets.

    Parameters
    ----------
    vertex_sets : array_like (N, n, d)
        Vertex coordinates of each polytope, vertices in the reference's order.
    reference : (n, d) array
        The centred reference shape r_a.
    similar : bool
        Allow a scale s^i > 0 per polytope (F-1); otherwise s^i = 1 is enforced.
    tol : float
        Allowed max vertex mismatch, relative to the reference circumradius.

    Raises ``ShapeError`` with one line that names the polytope and the size
    of the mismatch for: non-finite values, wrong dimension or vertex count,
    coincident vertices, mirror images (det -1), non-congruent/non-similar sets.
    """
    ref = np.asarray(reference, dtype=float)
    n, d = ref.shape
    size = float(np.max(np.linalg.norm(ref, axis=1)))
    rank = int(np.linalg.matrix_rank(ref, tol=1e-9 * size))
    sets = _checked_vertex_sets(vertex_sets, n, d, label, offset)
    if not sets:
        return np.zeros((0, d)), np.zeros((0, d, d)), np.zeros(0)
    if rank <= d - 2 and d >= 2:
        warnings.warn(f"the reference spans {rank} of {d} dimensions, so the rotation of each "
                      f"{label} is not unique (Lemma 3.2); taking the rotation of least angle",
                      RotationNotUniqueWarning, stacklevel=2)
    ref_sq = float(np.sum(ref * ref))
    ref_u, ref_s, ref_vt = np.linalg.svd(ref, full_matrices=False)
    ill_conditioned = rank >= 1 and ref_s[rank - 1] < 1e-5 * ref_s[0]
    centroids = np.empty((len(sets), d))
    rotations = np.empty((len(sets), d, d))
    scales = np.empty(len(sets))
    for i, v in enumerate(sets):
        name = f"{label} {i + offset}"
        c = v.mean(axis=0)
        q = v - c
        m = q.T @ ref
        if ill_conditioned:
            o = _rotation_from_reference_svd(q, ref_u, ref_s, ref_vt, rank)
        else:
            o = _least_angle_rotation(m, rank)
        s = float(np.sum(o * m)) / ref_sq if similar else 1.0
        mismatch = float(np.max(np.linalg.norm(q - s * ref @ o.T, axis=1)))
        # relative to the shape, but never finer than the input's own resolution (coordinates ~1e9)
        allowed = max(tol * size * max(s, 1.0), 8 * np.finfo(float).eps * float(np.max(np.abs(v))))
        if s <= 0 or mismatch > allowed:
            _explain_mismatch(name, q, ref, m, similar, mismatch, allowed, rank)
        centroids[i], rotations[i], scales[i] = c, o, s
    return centroids, rotations, scales


def _explain_mismatch(name, q, ref, m, similar, mismatch, allowed, rank):
    d = ref.shape[1]
    if rank >= d:   # a mirror image fits with an orthogonal matrix of det -1
        u, _, vt = np.linalg.svd(m)
        o = u @ vt
        if np.linalg.det(o) < 0:
            s = float(np.sum(o * m)) / float(np.sum(ref * ref)) if similar else 1.0
            mirror = float(np.max(np.linalg.norm(q - s * ref @ o.T, axis=1)))
            if mirror <= allowed:
                raise ShapeError(f"{name} is a mirror image of the reference (its best fit has "
                                 f"det -1); as a rotation the vertex mismatch is {mismatch:.3g} > "
                                 f"{allowed:.3g}")
    kind = "similar" if similar else "congruent"
    raise ShapeError(f"{name} is not {kind} to the reference: max vertex mismatch {mismatch:.3g} "
                     f"exceeds the tolerance {allowed:.3g}")
