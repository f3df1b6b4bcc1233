"""Batched rotation groups SO(d) with the maps that Lie-group integrators need.

Every class here stores N rotations in one array and vectorises over them.
The integrators only ever move a rotation by a *retraction*

    O  ->  psi(xi) O,        xi in so(d),

so rotations stay in SO(d) by construction (Lemma 2.1 holds to round-off,
not by projection).  ``psi`` is the exponential map where it has a cheap
closed form, otherwise the Cayley map; ``dpsi_inv`` is the inverse of its
right-trivialised differential, which Runge-Kutta-Munthe-Kaas methods need.

The model's coupling term is the skew part of the mean field (A-1, A-2):

    sum_k (O_k O_i^T - O_i O_k^T) = S O_i^T - O_i S^T,    S = sum_k w_k O_k,

which costs O(N d^3) instead of O(N^2 d^3).  ``mean_field`` computes S and
``coupling`` the skew kernel S O_i^T - O_i S^T, an element of so(d) in the
group's own representation; ``model.lohe_torque`` turns it into the torque.

Representations
---------------
``SO2``  angles theta (N,); so(2) as scalars w with hat(w) = w J.  On SO(2)
         the first-order model is exactly Kuramoto: theta_i' = kappa/N sum sin(theta_k - theta_i).
``SO3``  matrices in structure-of-arrays layout (3, 3, N); so(3) as vectors (3, N).
         Stacked 3x3 products in array-of-structures layout are slow in numpy;
         in SoA every entry is a contiguous length-N vector.
``SOn``  any d >= 2: matrices (N, d, d); so(d) as skew matrices (N, d, d).
         Cayley map without per-matrix solves (``cayley``): closed forms through
         so(4) = so(3) + so(3) for d = 4, batched matrix products otherwise.
``SO4``  d = 4: matrices (N, 4, 4) as in ``SOn``; so(4) as its self-dual parts (6, N),
         structure-of-arrays, so a step's increments never pass through 4x4 skew matrices.
"""

from .base import RotationGroup, polar_newton_schulz
from .so2 import SO2
from .so3 import SO3
from .so4 import SO4
from .son import SOn

__all__ = ["SO2", "SO3", "SO4", "SOn", "RotationGroup", "group_for", "polar_newton_schulz"]


def group_for(dim: int, representation: str = "auto") -> RotationGroup:
    """The cheapest exact representation of SO(dim), or the one asked for.

    ``auto``: angles for d = 2, SoA Cayley for d = 3, matrices for d >= 4.
    ``matrix``: the general (N, d, d) representation for any d (the full model); for d = 4
    its algebra is held in self-dual coordinates (``SO4``).
    """
    if representation == "auto":
        if dim == 2:
            return SO2()
        if dim == 3:
            return SO3("cayley")
        return SO4() if dim == 4 else SOn(dim)
    if representation == "angle":
        if dim != 2:
            raise ValueError("the angle representation exists only for d = 2")
        return SO2()
    if representation in ("so3", "so3-cayley", "so3-exp"):
        if dim != 3:
            raise ValueError("the so3 representation exists only for d = 3")
        return SO3("exp" if representation == "so3-exp" else "cayley")
    if representation == "matrix":
        return SO4() if dim == 4 else SOn(dim)
    raise ValueError(f"unknown rotation representation {representation!r}")
