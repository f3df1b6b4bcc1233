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

#: rows of the flattened (S O_n^T)^T whose differences are the vector of S O_n^T - O_n S^T
_KERNEL_PLUS, _KERNEL_MINUS = np.array([5, 6, 1]), np.array([7, 2, 3])


def _hat3(w):
    """(3, N) vectors -> (3, 3, N) skew matrices (SoA)."""
    z = np.zeros_like(w[0])
    return np.array([[z, -w[2], w[1]], [w[2], z, -w[0]], [-w[1], w[0], z]])


#: rows (1, 2, 0) and (2, 0, 1): a vector's components rolled by one and by two
_ROLL1, _ROLL2 = np.array([1, 2, 0]), np.array([2, 0, 1])


def _cross3(a, b):
    """Cross products a x b of (3, ...) arrays along their first axis, componentwise:
    (a1 b2 - a2 b1, a2 b0 - a0 b2, a0 b1 - a1 b0) = roll1(a) roll2(b) - roll2(a) roll1(b)."""
    out = a.take(_ROLL1, axis=0) * b.take(_ROLL2, axis=0)
    out -= a.take(_ROLL2, axis=0) * b.take(_ROLL1, axis=0)
    return out


def _rodrigues_coefficients(th2):
    """(sin t / t, (1 - cos t) / t^2) at t^2 = th2, by their series below t = 1e-4.

    (1 - cos t) / t^2 is evaluated as 2 sin^2(t/2) / t^2, which does not cancel for small t.
    """
    small = th2 < 1e-8
    any_small = bool(np.any(small))
    ths = np.sqrt(np.where(small, 1.0, th2) if any_small else th2)
    half = np.sin(0.5 * ths) / ths
    a, b = np.sin(ths) / ths, 2.0 * half * half
    if any_small:
        a = np.where(small, 1.0 - th2 / 6.0 + th2 * th2 / 120.0, a)
        b = np.where(small, 0.5 - th2 / 24.0 + th2 * th2 / 720.0, b)
    return a, b


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
        """r_n g_n for every n: sum over k of r[:, k] g[k], elementwise along the agents."""
        out = r[:, 0, None] * g[0]
        out += r[:, 1, None] * g[1]
        out += r[:, 2, None] * g[2]
        return out

    def retract(self, xi: Array, g: Array) -> Array:
        """psi(W) O = O + a W O + b W (W O), the columns of W O being w x (column of O).

        Cayley: a = c, b = c/2 with c = 1 / (1 + |w|^2 / 4), i.e. cay(W) = I + c (W + W^2/2);
        exp (Rodrigues): a = sin t / t, b = (1 - cos t) / t^2 at t = |w|.  Either is a
        rotation to round-off for every w (Lemma 2.1).
        """
        x2 = xi * xi
        th2 = x2[0] + x2[1] + x2[2]
        if self.retraction == "cayley":
            a = 1.0 / (1.0 + 0.25 * th2)
            b = 0.5 * a
        else:
            a, b = _rodrigues_coefficients(th2)
        w = xi[:, None]                                 # (3, 1, N): one w per column
        u = _cross3(w, g)                               # W O
        v = _cross3(w, u)                               # W (W O)
        out = a * u
        out += b * v
        out += g
        return out

    def dpsi_inv(self, xi: Array, a: Array) -> Array:
        wxa = _cross3(xi, a)
        if self.retraction == "cayley":
            out = a - 0.5 * wxa
            xa = xi * a
            out += (0.25 * (xa[0] + xa[1] + xa[2])) * xi
            return out
        x2 = xi * xi
        th2 = x2[0] + x2[1] + x2[2]
        small = th2 < 1e-6                        # |w| < 1e-3
        if np.any(small):
            ths = np.sqrt(np.where(small, 1.0, th2))
            coef = np.where(small, 1.0 / 12.0 + th2 / 720.0 + th2 * th2 / 30240.0,
                            (1.0 - 0.5 * ths / np.tan(0.5 * ths)) / (ths * ths))
        else:
            # (1 - (t/2) cot(t/2)) / t^2, series 1/12 + t^2/720 + t^4/30240 below 1e-3
            ths = np.sqrt(th2)
            coef = (1.0 - 0.5 * ths / np.tan(0.5 * ths)) / th2
        out = a - 0.5 * wxa
        out += coef * _cross3(xi, wxa)
        return out

    def mean_field(self, g: Array, weights: np.ndarray | None = None) -> MeanField:
        flat = g.reshape(9, -1)
        s = flat.sum(axis=1) if weights is None else flat @ weights
        return s.reshape(3, 3)

    def neighbour_fields(self, g: Array, weights: SparseWeights) -> Array:
        flat = g.reshape(9, -1)
        return np.ascontiguousarray((weights @ flat.T).T).reshape(3, 3, -1)    # (3, 3, n) SoA

    def coupling(self, g: Array, s: MeanField) -> Array:
        if isinstance(s, np.ndarray) and s.ndim == 3:   # one field per row: (S_n O_n^T)[:, c]
            a0, a1, a2 = (np.einsum("ijn,jn->in", s, g[c]) for c in range(3))
            return np.array([a1[2] - a2[1], a2[0] - a0[2], a0[1] - a1[0]])
        # column c of S O_n^T is S (row c of O_n): one product, a[c] = S g[c]
        a = np.matmul(s, g).reshape(9, -1)       # a[3c + i] = (S O_n^T)[i, c]
        return a[_KERNEL_PLUS] - a[_KERNEL_MINUS]

    def tangent(self, a: Array, g: Array) -> Array:
        return self._compose(_hat3(a), g)

    def project(self, g: Array) -> Array:
        return self.from_matrices(polar_newton_schulz(self.to_matrices(g)))
