"""SO(2) as angles: exp is addition, the first-order model (A-2) is Kuramoto."""

import numpy as np

from .base import RotationGroup


class SO2(RotationGroup):
    """SO(2) as angles; exp is addition, so every Lie method is a classical RK method on angles."""

    dim = 2
    name = "angle"
    retraction = "exp"
    abelian = True

    def identity(self, n):
        return np.zeros(n)

    def from_matrices(self, mats):
        mats = np.asarray(mats, dtype=float)
        return np.arctan2(mats[:, 1, 0], mats[:, 0, 0])

    def to_matrices(self, g):
        c, s = np.cos(g), np.sin(g)
        return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)

    def flat(self, g):
        c, s = np.cos(g), np.sin(g)
        return np.stack([c, -s, s, c], axis=1)

    def count(self, g):
        return g.shape[0]

    def take(self, g, idx):
        return g[idx]

    def put(self, g, idx, values):
        g[idx] = values

    def concat(self, parts):
        return np.concatenate(parts)

    def rotate(self, g, r):
        c, s = np.cos(g), np.sin(g)
        return np.stack([c * r[0] - s * r[1], s * r[0] + c * r[1]], axis=1)

    def algebra_zeros(self, n):
        return np.zeros(n)

    def algebra_take(self, a, idx):
        return a[idx]

    def algebra_concat(self, parts):
        return np.concatenate(parts)

    def algebra_from_skew(self, w):
        return np.asarray(w, dtype=float)[:, 1, 0].copy()

    def algebra_to_skew(self, a):
        z = np.zeros_like(a)
        return np.stack([np.stack([z, -a], -1), np.stack([a, z], -1)], -2)

    def algebra_sq_norm(self, a):
        return 2.0 * a * a

    def algebra_scale_rows(self, a, c):
        return a * c

    def retract(self, xi, g):
        return g + xi

    def dpsi_inv(self, xi, a):
        return a

    _trig = (None, None, None)

    def _cos_sin(self, g):
        """cos and sin of the angles, reused while the mean field and coupling see one array."""
        if self._trig[0] is not g:
            self._trig = (g, np.cos(g), np.sin(g))
        return self._trig[1], self._trig[2]

    def mean_field(self, g, weights=None):
        c, s = self._cos_sin(g)
        if weights is None:
            return complex(c.sum(), s.sum())
        return complex(c @ weights, s @ weights)

    def coupling(self, g, s):
        # S R(theta)^T - R(theta) S^T = 2 Im(Z e^{-i theta}) J
        c, sn = self._cos_sin(g)
        return 2.0 * (s.imag * c - s.real * sn)

    def tangent(self, a, g):
        raise TypeError("projection methods need a matrix representation; use SOn(2)")

    def project(self, g):
        return g
