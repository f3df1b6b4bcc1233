"""SO(d) for any d >= 2 as (N, d, d) matrices with the Cayley map (exp for d = 2)."""

from typing import Any

import numpy as np

from .base import (
    RECYCLED_MIN_BYTES,
    Array,
    MeanField,
    RowsFirstGroup,
    SparseWeights,
    polar_newton_schulz,
    recycled,
    row_blocks,
    row_sum,
    rows_product,
    scratch,
)
from .cayley import cayley_series, dcay_inv_series
from .so4_quaternions import cayley4_retract, dcay_inv4, quaternion_pairs, so4_split, unit_pairs

#: J G for a (N, 2, 2) batch G is (rows of G reversed) times these signs, J = [[0, -1], [1, 0]]
_J_SIGNS = np.array([[-1.0], [1.0]])


class SOn(RowsFirstGroup):
    """SO(d) for any d >= 2 as (N, d, d) matrices, with the Cayley map (exp for d = 2).

    cay(W) = (I - W/2)^{-1} (I + W/2),   dcay^{-1}_W(A) = (I - W/2) A (I + W/2).
    Both are exact and need no matrix exponential, which is what makes a
    4th-order Munthe-Kaas step affordable for d >= 4.  Neither needs a per-matrix
    LAPACK call either: for d = 4 closed forms through so(4) = so(3) + so(3) and unit
    quaternion pairs (``so4``), for the others batched matrix products (``cayley``).
    For d = 4 the pairs of O and the so(4) parts of Theta are kept by identity while the
    stages of a step reuse them: arrays handed to ``retract`` and ``dpsi_inv`` must not be
    modified in place afterwards (no integrator does).
    """

    name = "matrix"

    def __init__(self, dim: int) -> None:
        if dim < 2:
            raise ValueError("dimension must be >= 2")
        self.dim = dim
        self._eye = np.eye(dim)
        # SO(2) is abelian with a closed-form exp: use it, so this full matrix model runs
        # the same discrete scheme as the angle representation
        self.abelian = dim == 2
        self.retraction = "exp" if dim == 2 else "cayley"

    def identity(self, n: int) -> Array:
        return np.repeat(self._eye[None], n, axis=0)

    def from_matrices(self, mats: np.ndarray) -> Array:
        return np.array(mats, dtype=float)

    def to_matrices(self, g: Array) -> np.ndarray:
        return g

    def rotate(self, g: Array, r: np.ndarray) -> np.ndarray:
        return g @ r

    def algebra_zeros(self, n: int) -> Array:
        return np.zeros((n, self.dim, self.dim))

    def algebra_from_skew(self, w: np.ndarray) -> Array:
        """The skew part (W - W^T) / 2: a matrix skew to round-off (as read from a message) is
        made skew exactly, so the algebra holds only so(d); an exactly skew W is returned as
        it is (halving a doubled float is exact)."""
        w = np.asarray(w, dtype=float)
        return 0.5 * (w - np.swapaxes(w, -1, -2))

    def algebra_to_skew(self, a: Array) -> np.ndarray:
        return a

    def algebra_sq_norm(self, a: Array) -> np.ndarray:
        return np.sum(a * a, axis=(1, 2))

    def algebra_scale_rows(self, a: Array, c: np.ndarray) -> Array:
        return a * np.asarray(c)[:, None, None]

    def retract(self, xi: Array, g: Array) -> Array:
        if self.dim == 2:
            # exp(t J) G = cos(t) G + sin(t) J G,  J G = (-row 1 of G, row 0 of G)
            t = xi[:, 1, 0, None, None]
            out = np.cos(t) * g
            out += np.sin(t) * (g[:, ::-1] * _J_SIGNS)
            return out
        if self.dim == 4:
            out, pair = cayley4_retract(self._so4_parts(xi), self._quaternion_pairs(g))
            self._retracted = (out, pair)
            return out
        return cayley_series(xi, g)

    _pairs: tuple[Any, Any] = (None, None)
    _retracted: tuple[Any, Any] = (None, None)
    _parts: tuple[Any, Any] = (None, None)

    def _so4_parts(self, xi):
        """so4_split(Theta), kept for dpsi_inv at the same Theta (RKMK: the same stage)."""
        cached, parts = self._parts
        if cached is not xi:
            parts = so4_split(xi)
            self._parts = (xi, parts)
        return parts

    def _quaternion_pairs(self, g):
        """O = L(p) R(q) for d = 4, kept while the stages of a step retract around one O.

        The pair of the last retracted O is known (``cayley4_retract``): the O a step ends
        on is the next step's base, and its pair is renormalised (so that round-off does not
        build up over steps) instead of read off the matrices again.
        """
        cached, pairs = self._pairs
        if cached is not g:
            done, pairs = self._retracted
            pairs = quaternion_pairs(g) if done is not g else unit_pairs(pairs)
            self._pairs = (g, pairs)
        return pairs

    def dpsi_inv(self, xi: Array, a: Array) -> Array:
        if self.dim == 2:
            return a
        if self.dim == 4:
            return dcay_inv4(xi, a, self._so4_parts(xi))
        return dcay_inv_series(xi, a)

    def mean_field(self, g: Array, weights: np.ndarray | None = None) -> MeanField:
        # BLAS products on one thread each: summing over the leading axis of (N, d, d) is slower
        return row_sum(g.reshape(len(g), -1), weights).reshape(self.dim, self.dim)

    def neighbour_fields(self, g: Array, weights: SparseWeights) -> Array:
        d = self.dim
        return np.asarray(weights @ g.reshape(len(g), d * d)).reshape(-1, d, d)

    def coupling(self, g: Array, s: MeanField) -> Array:
        d = self.dim
        if g.nbytes < RECYCLED_MIN_BYTES and np.ndim(s) == 2:     # a few rows: one block
            b = np.matmul(g.reshape(-1, d), np.ascontiguousarray(np.transpose(s)))
            b = b.reshape(g.shape)
            return np.swapaxes(b, 1, 2) - b
        out = recycled(g.shape)
        if np.ndim(s) == 3:                      # one field per row
            b = np.matmul(g, np.swapaxes(s, 1, 2), out=scratch("coupling.fields", g.shape))
            return np.subtract(np.swapaxes(b, 1, 2), b, out=out)
        s_t = np.ascontiguousarray(np.transpose(s))
        rows, blocks = row_blocks(g.shape)       # B = O S^T and B^T - B a block at a time
        product = scratch("coupling", (rows * d, d))
        for block in blocks:
            n = block.stop - block.start
            b = rows_product(g[block].reshape(-1, d), s_t, out=product[:n * d])
            b = b.reshape(n, d, d)
            np.subtract(np.swapaxes(b, 1, 2), b, out=out[block])
        return out

    def tangent(self, a: Array, g: Array) -> Array:
        return a @ g

    def project(self, g: Array) -> Array:
        return polar_newton_schulz(g)
