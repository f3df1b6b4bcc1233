"""SO(4) as (N, 4, 4) matrices with so(4) in self-dual coordinates, structure-of-arrays (6, N).

so(4) = so(3) + so(3): W x = a x - x b for pure quaternions a, b (``so4``).  The algebra
arrays of this representation are the parts (a, b) stacked as six length-N rows, so every
operation an integrator does on increments and slopes (linear combinations, the inverse
Cayley differential, the retraction) runs on contiguous vectors, and no (N, 4, 4) skew
matrix is built or split inside a step: the Lohe kernel S O_i^T - O_i S^T (A-1, A-2) comes
out in these coordinates from one (N, 16) x (16, 6) product, and the Cayley retraction
is two quaternion products per rotation (``cayley4_retract``).  Rotations stay (N, 4, 4)
matrices, read by every other part of the package as for any d.
"""

import numpy as np

from .base import Array, ComponentAlgebra, MeanField
from .so4_quaternions import cayley4_retract, coupling_parts4, dcay_inv_parts, so4_join, so4_split
from .son import SOn


class SO4(ComponentAlgebra, SOn):
    """SO(4): rotations (N, 4, 4), so(4) as (6, N) self-dual parts; Cayley map in closed form.

    ``name`` stays "matrix": the rotations are the matrices of ``SOn``, only the algebra
    layout differs.  The pair O = L(p) R(q) of the base rotation is kept by identity while
    the stages of a step retract around it, and the pair of the last retracted O is kept
    for the next step: arrays handed to ``retract`` must not be modified in place afterwards.
    """

    algebra_rows = 6

    def __init__(self) -> None:
        super().__init__(4)

    # -- Lie algebra: (6, N) ----------------------------------------------
    def algebra_from_skew(self, w: np.ndarray) -> Array:
        return so4_split(np.asarray(w, dtype=float))

    def algebra_to_skew(self, a: Array) -> np.ndarray:
        return so4_join(a)

    def algebra_sq_norm(self, a: Array) -> np.ndarray:
        """|W|_F^2 = 4 (|a|^2 + |b|^2): the six basis matrices are orthogonal, each of norm 2."""
        return 4.0 * np.einsum("in,in->n", a, a)

    def algebra_scale_rows(self, a: Array, c: np.ndarray) -> Array:
        return a * c

    # -- maps the integrators use ------------------------------------------
    def retract(self, xi: Array, g: Array) -> Array:
        out, pair = cayley4_retract(xi, self._quaternion_pairs(g))
        self._retracted = (out, pair)
        return out

    def dpsi_inv(self, xi: Array, a: Array) -> Array:
        return dcay_inv_parts(xi, a)

    def coupling(self, g: Array, s: MeanField) -> Array:
        if np.ndim(s) == 3:                      # one field per row
            return so4_split(super().coupling(g, s))
        return coupling_parts4(g, np.asarray(s))

    def tangent(self, a: Array, g: Array) -> Array:
        return so4_join(a) @ g
