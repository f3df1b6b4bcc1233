"""SO(4) through pairs of unit quaternions: the closed-form Cayley map of so(4) and its inverse
differential, for the (N, 4, 4) matrix representation.

so(4) = so(3) + so(3).  With x in R^4 read as a quaternion, every W in so(4)
is W x = a x - x b for pure quaternions a (self-dual part) and b (anti-self-dual
part), the two parts commute and (a x)-squared is -|a|^2 x.  Writing
L(p) x = p x and R(q) x = x conj(q), the Cayley map factors exactly:

    cay(W) = L(P) R(Q) / (|P| |Q|),   P = (1 - s, a),  Q = (1 + s, b),  s = (|a|^2 - |b|^2)/4,

and the inverse differential at W of A = (c, e) is, in the same coordinates,

    c - a x c + (a.c) a/2 + (|b|^2 - |a|^2) c/4 + (b.e) a/2,
    e - b x e + (b.e) b/2 + (|a|^2 - |b|^2) e/4 + (a.c) b/2.

Every rotation is O = L(p) R(q) for a pair of unit quaternions (p, q) (defined up to a
common sign), so a retraction is two quaternion products, cay(W) O = L(P p) R(Q q) / (|P| |Q|);
the pair of the base rotation is read off O once and reused while the integrator retracts
around the same O (the stages of one step).
"""

import numpy as np

from .base import rows_product, scratch


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
_B4T = np.ascontiguousarray(_B4.T)
_T4T = np.ascontiguousarray(_T4.T)


def so4_split(w: np.ndarray) -> np.ndarray:
    """(N, 4, 4) skew matrices -> (6, N): the self-dual part a (rows 0-2), anti-self-dual b."""
    return np.ascontiguousarray((0.25 * rows_product(w.reshape(-1, 16), _B4T)).T)


def so4_join(ab: np.ndarray) -> np.ndarray:
    """(6, N) parts (a, b) -> (N, 4, 4) skew matrices W x = a x - x b."""
    return rows_product(ab.T, _B4).reshape(-1, 4, 4)


def _cayley_factors(ab):
    """(P, Q) as (4, N) unit quaternions with cay(W) = L(P) R(Q); ab = so4_split(W)."""
    sq = ab * ab
    a2 = sq[0] + sq[1] + sq[2]
    b2 = sq[3] + sq[4] + sq[5]
    s = 0.25 * (a2 - b2)
    p = np.empty((4, ab.shape[1]))
    q = np.empty((4, ab.shape[1]))
    p[0] = 1.0 - s
    q[0] = 1.0 + s
    p[1:] = ab[:3]
    q[1:] = ab[3:]
    p *= 1.0 / np.sqrt(p[0] * p[0] + a2)
    q *= 1.0 / np.sqrt(q[0] * q[0] + b2)
    return p, q


def pair_matrices(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """(4, N) quaternions p, q -> the (N, 4, 4) matrices of x -> p x conj(q)."""
    outer = np.multiply(p[:, None, :], q[None, :, :], out=scratch("so4.outer", (4, 4, p.shape[1])))
    return rows_product(outer.reshape(16, -1).T, _T4).reshape(-1, 4, 4)


def cayley4(w: np.ndarray) -> np.ndarray:
    """cay(W) for (N, 4, 4) skew matrices, as L(P) R(Q) / (|P| |Q|) (see the module)."""
    return pair_matrices(*_cayley_factors(so4_split(w)))


def quaternion_pairs(o: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(N, 4, 4) rotations -> unit quaternions (p, q), each (4, N), with O = L(p) R(q).

    <O, L(e_a) R(e_b)> = 4 p_a q_b: the rank-one matrix p q^T (``m`` below, times 4), read
    along its largest column.
    """
    m = np.ascontiguousarray(rows_product(o.reshape(-1, 16), _T4T).T).reshape(4, 4, -1)
    col = np.argmax(np.einsum("abn,abn->bn", m, m), axis=0)
    p = np.take_along_axis(m, col[None, None, :], axis=1)[:, 0, :]
    p *= 1.0 / np.sqrt(np.einsum("an,an->n", p, p))
    q = np.einsum("abn,an->bn", m, p)
    q *= 1.0 / np.sqrt(np.einsum("an,an->n", q, q))
    return p, q


def unit_pairs(pair: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """The pair (p, q) of (4, N) quaternions scaled to unit length."""
    return tuple(u * (1.0 / np.sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2] + u[3] * u[3]))
                 for u in pair)


def quaternion_product(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Hamilton products u v of (4, N) quaternion arrays, component by component.

    (u0 v0 - u.v, u0 v + v0 u + u x v) on length-N rows: no product of a (4, 16) table with a
    (16, N) array, which BLAS would spread over threads that stall on a busy machine.
    """
    u0, u1, u2, u3 = u
    v0, v1, v2, v3 = v
    out = np.empty((4, u.shape[1]))
    out[0] = u0 * v0 - u1 * v1 - u2 * v2 - u3 * v3
    out[1] = u0 * v1 + u1 * v0 + u2 * v3 - u3 * v2
    out[2] = u0 * v2 - u1 * v3 + u2 * v0 + u3 * v1
    out[3] = u0 * v3 + u1 * v2 - u2 * v1 + u3 * v0
    return out


def cayley4_retract(ab: np.ndarray, pair: tuple[np.ndarray, np.ndarray]
                    ) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray]]:
    """(cay(W) O, its pair) for ab = so4_split(W) and O = L(p) R(q), ``pair = (p, q)``.

    cay(W) O = L(P p) R(Q q): the pair (P p, Q q) of the result comes for free.
    """
    big_p, big_q = _cayley_factors(ab)
    new_pair = (quaternion_product(big_p, pair[0]), quaternion_product(big_q, pair[1]))
    return pair_matrices(*new_pair), new_pair


#: flat indices of the entries (i, j) above the diagonal of a 4x4 matrix: (0, 1), (0, 2),
#: (0, 3), (1, 2), (1, 3), (2, 3); and of their transposes (j, i)
_UPPER = (1, 2, 3, 6, 7, 11)
_LOWER = (4, 8, 12, 9, 13, 14)


def coupling_parts4(o: np.ndarray, s: np.ndarray) -> np.ndarray:
    """so4_split(S O_i^T - O_i S^T) as (6, N), for (N, 4, 4) rotations and one (4, 4) S.

    B = O S^T by one (4N, 4) x (4, 4) product; the kernel's entries above the diagonal are
    w_ij = B_ji - B_ij, one subtraction each (exactly 0 where S O^T is symmetric, e.g. one
    agent), and so4_split reads them in pairs: a = -(w01 + w23, w02 - w13, w03 + w12) / 2,
    b = (w01 - w23, w02 + w13, w03 - w12) / 2.  No transposed (N, 4, 4) copy is made.
    """
    n = len(o)
    b = rows_product(o.reshape(-1, 4), np.ascontiguousarray(s.T),
                     out=scratch("so4.product", (4 * n, 4))).reshape(n, 16).T
    w = scratch("so4.upper", (6, n))
    for k, (up, low) in enumerate(zip(_UPPER, _LOWER)):
        np.subtract(b[low], b[up], out=w[k])
    out = np.empty((6, n))
    for k, (first, second, sign) in enumerate(((0, 5, 1.0), (1, 4, -1.0), (2, 3, 1.0))):
        np.add(w[first], sign * w[second], out=out[k])
        np.subtract(w[first], sign * w[second], out=out[k + 3])
    out[:3] *= -0.5
    out[3:] *= 0.5
    return out


def _cross(u, v):
    return np.array([u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2],
                     u[0] * v[1] - u[1] * v[0]])


def dcay_inv4(w: np.ndarray, x: np.ndarray, ab: np.ndarray | None = None) -> np.ndarray:
    """(I - W/2) A (I + W/2) for (N, 4, 4) skew W and A, in self-dual coordinates.

    ``ab``: so4_split(W) when the caller has it already.
    """
    ab = so4_split(w) if ab is None else ab
    return so4_join(dcay_inv_parts(ab, so4_split(x)))


def dcay_inv_parts(ab: np.ndarray, ce: np.ndarray) -> np.ndarray:
    """``dcay_inv4`` in self-dual coordinates: (6, N) parts of W and of A -> (6, N) parts."""
    a, b, c, e = ab[:3], ab[3:], ce[:3], ce[3:]
    a2 = np.einsum("in,in->n", a, a)
    b2 = np.einsum("in,in->n", b, b)
    half_ac = 0.5 * np.einsum("in,in->n", a, c)
    half_be = 0.5 * np.einsum("in,in->n", b, e)
    quarter = 0.25 * (b2 - a2)
    mixed = half_ac + half_be
    out = np.empty_like(ce)
    out[:3] = (1.0 + quarter) * c - _cross(a, c) + mixed * a
    out[3:] = (1.0 - quarter) * e - _cross(b, e) + mixed * b
    return out
