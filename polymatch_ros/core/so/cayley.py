"""The Cayley map of so(d) and its inverse differential, batched without per-matrix solves.

    cay(W) = (I - W/2)^{-1} (I + W/2) = 2 (I - W/2)^{-1} - I,
    dcay^{-1}_W(A) = (I - W/2) A (I + W/2).

``np.linalg.solve`` on N small systems pays a LAPACK call per matrix; the forms
here cost a few batched matrix products (d >= 5) or a few vector operations on
length-N arrays (d = 4).  Both are the exact Cayley map, to round-off.

d = 4: so(4) = so(3) + so(3).  With x in R^4 read as a quaternion, every W in so(4)
is W x = a x - x b for pure quaternions a (self-dual part) and b (anti-self-dual
part), the two parts commute and (a x)-squared is -|a|^2 x.  Writing
L(p) x = p x and R(q) x = x conj(q), the Cayley map factors exactly:

    cay(W) = L(P) R(Q) / (|P| |Q|),   P = (1 - s, a),  Q = (1 + s, b),  s = (|a|^2 - |b|^2)/4,

and the inverse differential at W of A = (c, e) is, in the same coordinates,

    c - a x c + (a.c) a/2 + (|b|^2 - |a|^2) c/4 + (b.e) a/2,
    e - b x e + (b.e) b/2 + (|a|^2 - |b|^2) e/4 + (a.c) b/2.

d >= 5: with M = -W^2/4 (symmetric, 0 <= M <= |W|_F^2/8), (I - W/2)^{-1} =
(I + W/2)(I + M)^{-1} and (I + M)^{-1} = prod_{j<k} (I + (-M)^(2^j)) to round-off once
|M|^(2^k) < 2^-60.  A rotation whose |W|_F^2/8 exceeds SERIES_LIMIT is solved by LAPACK
instead (a choice made by that row alone); k follows the largest |W| of the others, so a
row's result depends on the rest of the batch only below round-off.
"""

import numpy as np

#: rows with |W|_F^2 / 8 (a bound of |M|_2) above this are solved by LAPACK
SERIES_LIMIT = 1.0 / 16.0
#: the product's remainder |M|^(2^k) must fall below this
SERIES_ROUNDOFF = 2.0 ** -60


def _quaternion_tables():
    """(T, B): T[(alpha, beta), (i, j)] = L(e_alpha) R(e_beta); B: the so(4) basis L_c, R_c."""
    # e_alpha e_beta = sum_gamma mult[alpha, beta, gamma] e_gamma (Hamilton's table)
    mult = np.zeros((4, 4, 4))
    prod = {(0, 0): (1, 0), (1, 1): (-1, 0), (2, 2): (-1, 0), (3, 3): (-1, 0),
            (1, 2): (1, 3), (2, 3): (1, 1), (3, 1): (1, 2),
            (2, 1): (-1, 3), (3, 2): (-1, 1), (1, 3): (-1, 2)}
    for k in range(4):
        prod[0, k] = prod[k, 0] = (1, k)
    for (alpha, beta), (sign, gamma) in prod.items():
        mult[alpha, beta, gamma] = sign
    conj = np.array([1.0, -1.0, -1.0, -1.0])
    left = np.einsum("abg->agb", mult)                           # L(e_a)[g, b]
    right = np.einsum("abg,b->bga", mult, conj)                  # R(e_b)[g, a]: x -> x conj(e_b)
    t = np.einsum("aik,bkj->abij", left, right).reshape(16, 16)
    basis = np.concatenate([left[1:], right[1:]]).reshape(6, 16)
    return t, basis


_T4, _B4 = _quaternion_tables()


def so4_split(w: np.ndarray) -> np.ndarray:
    """(N, 4, 4) skew matrices -> (6, N): the self-dual part a (rows 0-2), anti-self-dual b."""
    return 0.25 * (_B4 @ w.reshape(-1, 16).T)


def so4_join(ab: np.ndarray) -> np.ndarray:
    """(6, N) parts (a, b) -> (N, 4, 4) skew matrices W x = a x - x b."""
    return (ab.T @ _B4).reshape(-1, 4, 4)


def cayley4(w: np.ndarray) -> np.ndarray:
    """cay(W) for (N, 4, 4) skew matrices, as L(P) R(Q) / (|P| |Q|) (see the module)."""
    ab = so4_split(w)
    a, b = ab[:3], ab[3:]
    a2 = np.einsum("in,in->n", a, a)
    b2 = np.einsum("in,in->n", b, b)
    s = 0.25 * (a2 - b2)
    p = np.empty((w.shape[0], 4))
    q = np.empty((w.shape[0], 4))
    p[:, 0] = 1.0 - s
    q[:, 0] = 1.0 + s
    p[:, 1:] = a.T
    q[:, 1:] = b.T
    p /= np.sqrt(p[:, 0] ** 2 + a2)[:, None]
    q /= np.sqrt(q[:, 0] ** 2 + b2)[:, None]
    return ((p[:, :, None] * q[:, None, :]).reshape(-1, 16) @ _T4).reshape(-1, 4, 4)


def _cross(u, v):
    return np.array([u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2],
                     u[0] * v[1] - u[1] * v[0]])


def dcay_inv4(w: np.ndarray, x: np.ndarray) -> np.ndarray:
    """(I - W/2) A (I + W/2) for (N, 4, 4) skew W and A, in self-dual coordinates."""
    ab, ce = so4_split(w), so4_split(x)
    a, b, c, e = ab[:3], ab[3:], ce[:3], ce[3:]
    a2 = np.einsum("in,in->n", a, a)
    b2 = np.einsum("in,in->n", b, b)
    half_ac = 0.5 * np.einsum("in,in->n", a, c)
    half_be = 0.5 * np.einsum("in,in->n", b, e)
    quarter = 0.25 * (b2 - a2)
    out = np.empty_like(ab)
    out[:3] = (1.0 + quarter) * c - _cross(a, c) + (half_ac + half_be) * a
    out[3:] = (1.0 - quarter) * e - _cross(b, e) + (half_be + half_ac) * b
    return so4_join(out)


def cayley_series(w: np.ndarray, g: np.ndarray) -> np.ndarray:
    """cay(W) G for (N, d, d) skew W and matrices G, by batched products (d >= 5).

    Rows beyond SERIES_LIMIT are solved by LAPACK; the others by the product form of
    (I + M)^{-1} with as many factors as the largest of them needs (module docstring).
    """
    bound = np.einsum("nij,nij->n", w, w) / 8.0
    far = bound > SERIES_LIMIT
    if np.any(far):
        out = np.empty_like(g)
        near = ~far
        eye = np.eye(w.shape[1])
        half = 0.5 * w[far]
        out[far] = 2.0 * np.linalg.solve(eye - half, g[far]) - g[far]
        if np.any(near):
            out[near] = cayley_series(w[near], g[near])
        return out
    factors, largest = 1, float(np.max(bound, initial=0.0))
    while largest ** (2 ** factors) >= SERIES_ROUNDOFF:     # at most 4: largest <= 1/16
        factors += 1
    neg_m = 0.25 * (w @ w)                              # -M = W^2 / 4
    y = g + neg_m @ g
    for _ in range(factors - 1):
        neg_m = neg_m @ neg_m
        y += neg_m @ y
    y += 0.5 * (w @ y)                                  # (I + W/2) (I + M)^{-1} G
    y *= 2.0
    y -= g
    return y
