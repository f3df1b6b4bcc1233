"""SO(d) for any d >= 2 as (N, d, d) matrices with the Cayley map (exp for d = 2)."""

import numpy as np

from .base import RotationGroup, polar_newton_schulz


class SOn(RotationGroup):
    """SO(d) for any d >= 2 as (N, d, d) matrices, with the Cayley map (exp for d = 2).

    cay(W) = (I - W/2)^{-1} (I + W/2),   dcay^{-1}_W(A) = (I - W/2) A (I + W/2).
    Both are exact and need no matrix exponential, which is what makes a
    4th-order Munthe-Kaas step affordable for d >= 4.
    """

    name = "matrix"

    def __init__(self, dim):
        if dim < 2:
            raise ValueError("dimension must be >= 2")
        self.dim = dim
        self._eye = np.eye(dim)
        # SO(2) is abelian with a closed-form exp: use it, so this full matrix model runs
        # the same discrete scheme as the angle representation
        self.abelian = dim == 2
        self.retraction = "exp" if dim == 2 else "cayley"

    def identity(self, n):
        return np.repeat(self._eye[None], n, axis=0)

    def from_matrices(self, mats):
        return np.array(mats, dtype=float)

    def to_matrices(self, g):
        return g

    def count(self, g):
        return g.shape[0]

    def take(self, g, idx):
        return g[idx]

    def put(self, g, idx, values):
        g[idx] = values

    def concat(self, parts):
        return np.concatenate(parts, axis=0)

    def rotate(self, g, r):
        return g @ r

    def algebra_zeros(self, n):
        return np.zeros((n, self.dim, self.dim))

    def algebra_take(self, a, idx):
        return a[idx]

    def algebra_concat(self, parts):
        return np.concatenate(parts, axis=0)

    def algebra_from_skew(self, w):
        return np.array(w, dtype=float)

    def algebra_to_skew(self, a):
        return a

    def algebra_sq_norm(self, a):
        return np.sum(a * a, axis=(1, 2))

    def algebra_scale_rows(self, a, c):
        return a * np.asarray(c)[:, None, None]

    def retract(self, xi, g):
        if self.dim == 2:
            c, s = np.cos(xi[:, 1, 0]), np.sin(xi[:, 1, 0])
            rot = np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)
            return rot @ g
        half = 0.5 * xi
        return np.linalg.solve(self._eye - half, (self._eye + half) @ g)

    def dpsi_inv(self, xi, a):
        if self.dim == 2:
            return a
        half = 0.5 * xi
        return (self._eye - half) @ a @ (self._eye + half)

    def mean_field(self, g, weights=None):
        return g.sum(axis=0) if weights is None else np.tensordot(weights, g, axes=(0, 0))

    def coupling(self, g, s):
        d = self.dim
        b = (g.reshape(-1, d) @ s.T).reshape(-1, d, d)  # b_i = O_i S^T
        return np.swapaxes(b, 1, 2) - b

    def tangent(self, a, g):
        return a @ g

    def project(self, g):
        return polar_newton_schulz(g)
