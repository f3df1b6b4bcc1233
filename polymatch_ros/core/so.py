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
``coupling`` computes the right-hand side, returned as an element of so(d)
in the group's own representation.

Representations
---------------
``SO2``  angles theta (N,); so(2) as scalars w with hat(w) = w J.  On SO(2)
         the first-order model is exactly Kuramoto: theta_i' = kappa/N sum sin(theta_k - theta_i).
``SO3``  matrices in structure-of-arrays layout (3, 3, N); so(3) as vectors (3, N).
         Stacked 3x3 products in array-of-structures layout are slow in numpy;
         in SoA every entry is a contiguous length-N vector.
``SOn``  any d >= 2: matrices (N, d, d); so(d) as skew matrices (N, d, d).
         Cayley map through batched linear solves (no batched ``expm``).
"""

import numpy as np


class RotationGroup:
    """Interface shared by the batched SO(d) representations."""

    dim = 0
    name = "abstract"
    #: which map ``retract`` uses: "exp" or "cayley"
    retraction = "exp"
    #: True when rotations commute (SO(2)): dpsi_inv is the identity
    abelian = False

    # -- construction and conversion -------------------------------------
    def identity(self, n):
        raise NotImplementedError

    def from_matrices(self, mats):
        """(N, d, d) rotation matrices -> group array."""
        raise NotImplementedError

    def to_matrices(self, g):
        """Group array -> (N, d, d) rotation matrices."""
        raise NotImplementedError

    def flat(self, g):
        """(N, d*d) row-major matrix entries; Frobenius distances are Euclidean here."""
        return self.to_matrices(g).reshape(self.count(g), -1)

    def count(self, g):
        raise NotImplementedError

    def take(self, g, idx):
        raise NotImplementedError

    def put(self, g, idx, values):
        """Write rows ``idx`` of ``g`` in place."""
        raise NotImplementedError

    def concat(self, parts):
        raise NotImplementedError

    def rotate(self, g, r):
        """Apply every rotation to one vector r (d,): returns (N, d)."""
        raise NotImplementedError

    # -- Lie algebra -----------------------------------------------------
    def algebra_zeros(self, n):
        raise NotImplementedError

    def algebra_take(self, a, idx):
        raise NotImplementedError

    def algebra_concat(self, parts):
        raise NotImplementedError

    def algebra_from_skew(self, w):
        """(N, d, d) skew matrices -> algebra array."""
        raise NotImplementedError

    def algebra_to_skew(self, a):
        """Algebra array -> (N, d, d) skew matrices."""
        raise NotImplementedError

    def algebra_sq_norm(self, a):
        """Squared Frobenius norm of hat(a), per rotation: (N,)."""
        raise NotImplementedError

    def algebra_scale_rows(self, a, c):
        """Multiply row i of an algebra array by c[i]."""
        raise NotImplementedError

    # -- maps the integrators use ------------------------------------------
    def retract(self, xi, g):
        """psi(xi) O for each rotation; psi is exp or Cayley."""
        raise NotImplementedError

    def dpsi_inv(self, xi, a):
        """Inverse right-trivialised differential of psi at xi, applied to a."""
        raise NotImplementedError

    def mean_field(self, g, weights=None):
        """S = sum_k w_k O_k (representation-specific)."""
        raise NotImplementedError

    def coupling(self, g, s):
        """S O_i^T - O_i S^T for every rotation, as an algebra array."""
        raise NotImplementedError

    # -- embedding-space operations (projection baselines) ----------------
    def tangent(self, a, g):
        """hat(a) O in the embedding space (same layout as the group array)."""
        raise NotImplementedError

    def project(self, g):
        """Nearest rotation (polar factor) of each near-orthogonal matrix."""
        raise NotImplementedError


def _polar_newton_schulz(mats, tol=1e-15, max_iter=12):
    """Polar factor of near-orthogonal (N, d, d) matrices.

    Newton-Schulz X <- X (3 I - X^T X) / 2 converges quadratically when
    |X^T X - I| < 1; anything further away falls back to an SVD.
    """
    mats = np.array(mats, dtype=float)
    n, d, _ = mats.shape
    eye = np.eye(d)
    defect = np.linalg.norm(np.swapaxes(mats, 1, 2) @ mats - eye, axis=(1, 2))
    far = defect >= 0.5
    x = mats[~far]
    for _ in range(max_iter):
        gram = np.swapaxes(x, 1, 2) @ x
        if x.shape[0] == 0 or np.max(np.abs(gram - eye)) < tol:
            break
        x = 0.5 * x @ (3.0 * eye - gram)
    out = np.empty_like(mats)
    out[~far] = x
    if np.any(far):
        u, _, vt = np.linalg.svd(mats[far])
        det = np.linalg.det(u @ vt)
        u[..., -1] *= det[:, None]
        out[far] = u @ vt
    return out


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
        """cos and sin of the angles, reused when the mean field and the coupling see the same array."""
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


def _hat3(w):
    """(3, N) vectors -> (3, 3, N) skew matrices (SoA)."""
    z = np.zeros_like(w[0])
    return np.array([[z, -w[2], w[1]], [w[2], z, -w[0]], [-w[1], w[0], z]])


def _cross3(a, b):
    """Cross products of (3, N) vector arrays, componentwise (faster than np.cross here)."""
    return np.array([a[1] * b[2] - a[2] * b[1],
                     a[2] * b[0] - a[0] * b[2],
                     a[0] * b[1] - a[1] * b[0]])


class SO3(RotationGroup):
    """SO(3) in structure-of-arrays layout with closed-form maps.

    ``retraction="cayley"`` (default): cay(w) = I + c (W + W^2 / 2), c = 1 / (1 + |w|^2 / 4),
    with dcay^{-1}_w(a) = a - w x a / 2 + (w . a) w / 4 — rational, no trigonometry.
    ``retraction="exp"``: Rodrigues' formula with the closed-form dexp^{-1}.
    """

    dim = 3
    name = "so3"

    def __init__(self, retraction="cayley"):
        if retraction not in ("cayley", "exp"):
            raise ValueError("retraction must be 'cayley' or 'exp'")
        self.retraction = retraction

    def identity(self, n):
        return np.repeat(np.eye(3)[:, :, None], n, axis=2)

    def from_matrices(self, mats):
        return np.ascontiguousarray(np.asarray(mats, dtype=float).transpose(1, 2, 0))

    def to_matrices(self, g):
        return np.ascontiguousarray(g.transpose(2, 0, 1))

    def flat(self, g):
        return g.reshape(9, -1).T

    def count(self, g):
        return g.shape[2]

    def take(self, g, idx):
        return g[:, :, idx]

    def put(self, g, idx, values):
        g[:, :, idx] = values

    def concat(self, parts):
        return np.concatenate(parts, axis=2)

    def rotate(self, g, r):
        return np.einsum("ijn,j->ni", g, r)

    def algebra_zeros(self, n):
        return np.zeros((3, n))

    def algebra_take(self, a, idx):
        return a[:, idx]

    def algebra_concat(self, parts):
        return np.concatenate(parts, axis=1)

    def algebra_from_skew(self, w):
        w = np.asarray(w, dtype=float)
        return np.array([w[:, 2, 1], w[:, 0, 2], w[:, 1, 0]])

    def algebra_to_skew(self, a):
        return _hat3(a).transpose(2, 0, 1)

    def algebra_sq_norm(self, a):
        return 2.0 * np.sum(a * a, axis=0)

    def algebra_scale_rows(self, a, c):
        return a * c

    def _compose(self, r, g):
        return np.einsum("ikn,kjn->ijn", r, g)

    def retract(self, xi, g):
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
        b = np.where(small, 0.5 - th2 / 24.0 + th2 * th2 / 720.0, (1.0 - np.cos(ths)) / (ths * ths))
        k = _hat3(xi)
        k2 = np.einsum("ikn,kjn->ijn", k, k)
        r = a * k + b * k2
        r[0, 0] += 1.0
        r[1, 1] += 1.0
        r[2, 2] += 1.0
        return self._compose(r, g)

    def dpsi_inv(self, xi, a):
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

    def mean_field(self, g, weights=None):
        flat = g.reshape(9, -1)
        s = flat.sum(axis=1) if weights is None else flat @ weights
        return s.reshape(3, 3)

    def coupling(self, g, s):
        # column c of S O_n^T is S (row c of O_n): three (3x3)(3xN) BLAS products
        a0, a1, a2 = s @ g[0], s @ g[1], s @ g[2]
        return np.array([a1[2] - a2[1], a2[0] - a0[2], a0[1] - a1[0]])

    def tangent(self, a, g):
        return self._compose(_hat3(a), g)

    def project(self, g):
        return self.from_matrices(_polar_newton_schulz(self.to_matrices(g)))


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
        return _polar_newton_schulz(g)


def group_for(dim, representation="auto"):
    """The cheapest exact representation of SO(dim), or the one asked for.

    ``auto``: angles for d = 2, SoA Cayley for d = 3, matrices for d >= 4.
    ``matrix``: the general (N, d, d) representation for any d (the full model).
    """
    if representation == "auto":
        if dim == 2:
            return SO2()
        if dim == 3:
            return SO3("cayley")
        return SOn(dim)
    if representation == "angle":
        if dim != 2:
            raise ValueError("the angle representation exists only for d = 2")
        return SO2()
    if representation in ("so3", "so3-cayley", "so3-exp"):
        if dim != 3:
            raise ValueError("the so3 representation exists only for d = 3")
        return SO3("exp" if representation == "so3-exp" else "cayley")
    if representation == "matrix":
        return SOn(dim)
    raise ValueError(f"unknown rotation representation {representation!r}")
