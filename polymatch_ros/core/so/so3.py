"""SO(3) in structure-of-arrays layout with closed-form Cayley and exp maps."""

from collections.abc import Sequence

import numpy as np

from .base import (
    Array,
    ComponentAlgebra,
    MeanField,
    RotationGroup,
    RowIndex,
    SparseWeights,
    polar_newton_schulz,
)


def _hat3(w):
    """(3, N) vectors -> (3, 3, N) skew matrices (SoA)."""
    z = np.zeros_like(w[0])
    return np.array([[z, -w[2], w[1]], [w[2], z, -w[0]], [-w[1], w[0], z]])


def _cross3(a, b):
    """Cross products of (3, N) vector arrays, componentwise (faster than np.cross here)."""
    return np.array([a[1] * b[2] - a[2] * b[1],
                     a[2] * b[0] - a[0] * b[2],
                     a[0] * b[1] - a[1] * b[0]])


class SO3(ComponentAlgebra, RotationGroup):
    """SO(3) in structure-of-arrays layout with closed-form maps.

    ``retraction="cayley"`` (default): cay(w) = I + c (W + W^2 / 2), c = 1 / (1 + |w|^2 / 4),
    with dcay^{-1}_w(a) = a - w x a / 2 + (w . a) w / 4 — rational, no trigonometry.
    ``retraction="exp"``: Rodrigues' formula with the closed-form dexp^{-1}.
    """

    dim = 3
    name = "so3"
    algebra_rows = 3

    def __init__(self, retraction: str = "cayley") -> None:
        if retraction not in ("cayley", "exp"):
            raise ValueError("retraction must be 'cayley' or 'exp'")
        self.retraction = retraction

    def identity(self, n: int) -> Array:
        return np.repeat(np.eye(3)[:, :, None], n, axis=2)

    def from_matrices(self, mats: np.ndarray) -> Array:
        return np.ascontiguousarray(np.asarray(mats, dtype=float).transpose(1, 2, 0))

    def to_matrices(self, g: Array) -> np.ndarray:
        return np.ascontiguousarray(g.transpose(2, 0, 1))

    def flat(self, g: Array) -> np.ndarray:
        return g.reshape(9, -1).T

    def count(self, g: Array) -> int:
        return g.shape[2]

    def take(self, g: Array, idx: RowIndex) -> Array:
        return g[:, :, idx]

    def put(self, g: Array, idx: RowIndex, values: Array) -> None:
        g[:, :, idx] = values

    def concat(self, parts: Sequence[Array]) -> Array:
        return np.concatenate(parts, axis=2)

    def rotate(self, g: Array, r: np.ndarray) -> np.ndarray:
        return np.einsum("ijn,j->ni", g, r)

    def algebra_from_skew(self, w: np.ndarray) -> Array:
        w = np.asarray(w, dtype=float)
        return np.array([w[:, 2, 1], w[:, 0, 2], w[:, 1, 0]])

    def algebra_to_skew(self, a: Array) -> np.ndarray:
        return _hat3(a).transpose(2, 0, 1)

    def algebra_sq_norm(self, a: Array) -> np.ndarray:
        return 2.0 * np.sum(a * a, axis=0)

    def algebra_scale_rows(self, a: Array, c: np.ndarray) -> Array:
        return a * c

    def _compose(self, r, g):
        return np.einsum("ikn,kjn->ijn", r, g)

    def retract(self, xi: Array, g: Array) -> Array:
        if self.retraction == "cayley":
            th2 = np.sum(xi * xi, axis=0)
            c = 1.0 / (1.0 + 0.25 * th2)
            half_c = 0.5 * c
            x, y, z = xi
            r = np.empty((3, 3, xi.shape[1]))
            # I + c W + (c/2)(w w^T - |w|^2 I)
            diag = 1.0 - half_c * th2
            r[0, 0] = diag + half_c * x * x
            r[1, 1] = diag + half_c * y * y
            r[2, 2] = diag + half_c * z * z
            xy, xz, yz = half_c * x * y, half_c * x * z, half_c * y * z
            r[0, 1] = xy - c * z
            r[1, 0] = xy + c * z
            r[0, 2] = xz + c * y
            r[2, 0] = xz - c * y
            r[1, 2] = yz - c * x
            r[2, 1] = yz + c * x
            return self._compose(r, g)
        th = np.sqrt(np.sum(xi * xi, axis=0))
        small = th < 1e-4
        ths = np.where(small, 1.0, th)
        th2 = th * th
        a = np.where(small, 1.0 - th2 / 6.0 + th2 * th2 / 120.0, np.sin(ths) / ths)
        b = np.where(small, 0.5 - th2 / 24.0 + th2 * th2 / 720.0,
                     (1.0 - np.cos(ths)) / (ths * ths))
        k = _hat3(xi)
        k2 = np.einsum("ikn,kjn->ijn", k, k)
        r = a * k + b * k2
        r[0, 0] += 1.0
        r[1, 1] += 1.0
        r[2, 2] += 1.0
        return self._compose(r, g)

    def dpsi_inv(self, xi: Array, a: Array) -> Array:
        if self.retraction == "cayley":
            return a - 0.5 * _cross3(xi, a) + 0.25 * np.sum(xi * a, axis=0) * xi
        th = np.sqrt(np.sum(xi * xi, axis=0))
        small = th < 1e-3
        ths = np.where(small, 1.0, th)
        th2 = th * th
        # (1 - (t/2) cot(t/2)) / t^2, series 1/12 + t^2/720 + t^4/30240
        coef = np.where(small, 1.0 / 12.0 + th2 / 720.0 + th2 * th2 / 30240.0,
                        (1.0 - 0.5 * ths / np.tan(0.5 * ths)) / (ths * ths))
        wxa = _cross3(xi, a)
        return a - 0.5 * wxa + coef * _cross3(xi, wxa)

    def mean_field(self, g: Array, weights: np.ndarray | None = None) -> MeanField:
        flat = g.reshape(9, -1)
        s = flat.sum(axis=1) if weights is None else flat @ weights
        return s.reshape(3, 3)

    def neighbour_fields(self, g: Array, weights: SparseWeights) -> Array:
        flat = g.reshape(9, -1)
        return np.ascontiguousarray((weights @ flat.T).T).reshape(3, 3, -1)    # (3, 3, n) SoA

    def coupling(self, g: Array, s: MeanField) -> Array:
        if np.ndim(s) == 3:                      # one field per row: (S_n O_n^T)[:, c] per n
            a0, a1, a2 = (np.einsum("ijn,jn->in", s, g[c]) for c in range(3))
            return np.array([a1[2] - a2[1], a2[0] - a0[2], a0[1] - a1[0]])
        # column c of S O_n^T is S (row c of O_n): three (3x3)(3xN) BLAS products
        a0, a1, a2 = s @ g[0], s @ g[1], s @ g[2]
        return np.array([a1[2] - a2[1], a2[0] - a0[2], a0[1] - a1[0]])

    def tangent(self, a: Array, g: Array) -> Array:
        return self._compose(_hat3(a), g)

    def project(self, g: Array) -> Array:
        return self.from_matrices(polar_newton_schulz(self.to_matrices(g)))
