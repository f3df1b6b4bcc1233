"""SO(2) as angles: exp is addition, the first-order model (A-2) is Kuramoto."""


import numpy as np

from .base import Array, MeanField, RowsFirstGroup, SparseWeights

_add = np.add.reduce


class SO2(RowsFirstGroup):
    """SO(2) as angles; exp is addition, so every Lie method is a classical RK method on angles."""

    dim = 2
    name = "angle"
    retraction = "exp"
    abelian = True

    def identity(self, n: int) -> Array:
        return np.zeros(n)

    def from_matrices(self, mats: np.ndarray) -> Array:
        mats = np.asarray(mats, dtype=float)
        return np.arctan2(mats[:, 1, 0], mats[:, 0, 0])

    def to_matrices(self, g: Array) -> np.ndarray:
        c, s = np.cos(g), np.sin(g)
        return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)

    def flat(self, g: Array) -> np.ndarray:
        c, s = np.cos(g), np.sin(g)
        return np.stack([c, -s, s, c], axis=1)

    def rotate(self, g: Array, r: np.ndarray) -> np.ndarray:
        c, s = np.cos(g), np.sin(g)
        return np.stack([c * r[0] - s * r[1], s * r[0] + c * r[1]], axis=1)

    def algebra_zeros(self, n: int) -> Array:
        return np.zeros(n)

    def algebra_from_skew(self, w: np.ndarray) -> Array:
        return np.asarray(w, dtype=float)[:, 1, 0].copy()

    def algebra_to_skew(self, a: Array) -> np.ndarray:
        z = np.zeros_like(a)
        return np.stack([np.stack([z, -a], -1), np.stack([a, z], -1)], -2)

    def algebra_sq_norm(self, a: Array) -> np.ndarray:
        return 2.0 * a * a

    def algebra_scale_rows(self, a: Array, c: np.ndarray) -> Array:
        return a * c

    def retract(self, xi: Array, g: Array) -> Array:
        return g + xi

    def retract_each(self, xis: np.ndarray, g: Array) -> list[Array]:
        return list(g + xis)

    def dpsi_inv(self, xi: Array, a: Array) -> Array:
        return a

    _trig = (None, None, None)

    def _cos_sin(self, g):
        """cos and sin of the angles, reused while the mean field and coupling see one array."""
        if self._trig[0] is not g:
            self._trig = (g, np.cos(g), np.sin(g))
        return self._trig[1], self._trig[2]

    def mean_field(self, g: Array, weights: np.ndarray | None = None) -> MeanField:
        c, s = self._cos_sin(g)
        if weights is None:                       # ufunc reductions: ndarray.sum's wrapper costs
            return complex(_add(c), _add(s))      # more than summing a few angles
        return complex(c @ weights, s @ weights)

    def neighbour_fields(self, g: Array, weights: SparseWeights) -> Array:
        c, s = self._cos_sin(g)
        return weights @ (c + 1j * s)            # complex per row: the same formula below

    def coupling(self, g: Array, s: MeanField) -> Array:
        # S R(theta)^T - R(theta) S^T = 2 Im(Z e^{-i theta}) J
        c, sn = self._cos_sin(g)
        out = (2.0 * s.imag) * c                  # 2 (a - b) = 2a - 2b exactly: one ufunc less
        out -= (2.0 * s.real) * sn
        return out

    def tangent(self, a: Array, g: Array) -> Array:
        raise TypeError("projection methods need a matrix representation; use SOn(2)")

    def project(self, g: Array) -> Array:
        return g
