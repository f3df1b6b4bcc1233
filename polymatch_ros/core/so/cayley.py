"""The Cayley map of so(d) and its inverse differential, batched without per-matrix solves.

    cay(W) = (I - W/2)^{-1} (I + W/2) = 2 (I - W/2)^{-1} - I,
    dcay^{-1}_W(A) = (I - W/2) A (I + W/2).

``np.linalg.solve`` on N small systems pays a LAPACK call per matrix; the forms
here cost a few batched matrix products (d >= 5) or a few vector operations on
length-N arrays (d = 4).  Both are the exact Cayley map, to round-off.

d = 4: closed forms through so(4) = so(3) + so(3) (``so4``).

d >= 5: with M = -W^2/4 (symmetric, 0 <= M <= |W|_F^2/8), (I - W/2)^{-1} =
(I + W/2)(I + M)^{-1} and (I + M)^{-1} = prod_{j<k} (I + (-M)^(2^j)) to round-off once
|M|^(2^k) < 2^-60, or = sum_{j<n} (-M)^j (Horner: n - 1 products against 2k - 1) once
|M|^n < 2^-60, whichever takes fewer products (the sum, for the small W of a step).
A rotation whose |W|_F^2/8 exceeds SERIES_LIMIT is solved by LAPACK
instead (a choice made by that row alone); k follows the largest |W| of the others, so a
row's result depends on the rest of the batch only below round-off.

Both run over blocks of rows (``row_blocks``): a block's few temporaries stay in the CPU
caches between its products, where whole (N, d, d) arrays would go back and forth to memory.
Every row's operations are those of the whole batch, so the results are the same bits.
"""

import numpy as np

from .base import RECYCLED_MIN_BYTES, recycled, row_blocks, scratch

#: rows with |W|_F^2 / 8 (a bound of |M|_2) above this are solved by LAPACK
SERIES_LIMIT = 1.0 / 16.0
#: the product's remainder |M|^(2^k) must fall below this
SERIES_ROUNDOFF = 2.0 ** -60


def cayley_series(w: np.ndarray, g: np.ndarray) -> np.ndarray:
    """cay(W) G for (N, d, d) skew W and matrices G, by batched products (d >= 5).

    Rows beyond SERIES_LIMIT are solved by LAPACK; the others by the product form of
    (I + M)^{-1} with as many factors as the largest of them needs (module docstring).
    """
    bound = np.einsum("nij,nij->n", w, w) / 8.0
    largest = float(np.max(bound, initial=0.0))
    if largest > SERIES_LIMIT:
        far = bound > SERIES_LIMIT
        out = np.empty_like(g)
        near = ~far
        eye = np.eye(w.shape[1])
        half = 0.5 * w[far]
        out[far] = 2.0 * np.linalg.solve(eye - half, g[far]) - g[far]
        if np.any(near):
            out[near] = cayley_series(w[near], g[near])
        return out
    factors, terms = 1, 2
    while largest ** (2 ** factors) >= SERIES_ROUNDOFF:     # at most 4: largest <= 1/16
        factors += 1
    while largest ** terms >= SERIES_ROUNDOFF and terms < 2 ** factors:
        terms += 1
    if g.nbytes < RECYCLED_MIN_BYTES:    # a few rows: one block, fresh temporaries
        out = np.empty_like(g)
        _series_rows(w, g, out, [np.empty_like(g) for _ in range(3)], factors, terms)
        return out
    out = recycled(g.shape)
    rows, blocks = row_blocks(g.shape)
    temps = [scratch(f"cayley.{name}", (rows,) + g.shape[1:]) for name in ("half", "m", "spare")]
    for block in blocks:
        n = block.stop - block.start
        _series_rows(w[block], g[block], out[block], [t[:n] for t in temps], factors, terms)
    return out


def _series_rows(w: np.ndarray, g: np.ndarray, y: np.ndarray, temps: list[np.ndarray],
                 factors: int, terms: int) -> None:
    """y = cay(W) G for a block of rows: (I + W/2)(I + M)^{-1} G with ``terms`` or ``factors``."""
    half_buf, m_buf, spare = temps
    half = np.multiply(w, 0.5, out=half_buf)
    neg_m = np.matmul(half, half, out=m_buf)            # -M = W^2 / 4
    np.matmul(neg_m, g, out=y)
    y += g
    if terms - 1 < 2 * factors - 1:     # small W: G - M (G - M (G ...)), fewer products
        for _ in range(terms - 2):
            np.add(g, np.matmul(neg_m, y, out=spare), out=y)
    else:
        for _ in range(factors - 1):
            neg_m, spare = np.matmul(neg_m, neg_m, out=spare), neg_m
            y += np.matmul(neg_m, y, out=spare)
    y += np.matmul(half, y, out=spare)                  # (I + W/2) (I + M)^{-1} G
    y *= 2.0
    y -= g


def dcay_inv_series(w: np.ndarray, a: np.ndarray) -> np.ndarray:
    """dcay^{-1}_W(A) = (I - W/2) A (I + W/2) = B + B W/2, B = A - W/2 A, for (N, d, d) W, A."""
    if a.nbytes < RECYCLED_MIN_BYTES:    # a few rows: one block
        half = 0.5 * w
        b = a - np.matmul(half, a)
        b += np.matmul(b, half)
        return b
    out = recycled(a.shape)
    rows, blocks = row_blocks(a.shape)
    half_buf, prod_buf = (scratch(f"dcay.{name}", (rows,) + a.shape[1:])
                          for name in ("half", "product"))
    for block in blocks:
        n = block.stop - block.start
        half = np.multiply(w[block], 0.5, out=half_buf[:n])
        prod = np.matmul(half, a[block], out=prod_buf[:n])
        b = np.subtract(a[block], prod, out=out[block])
        b += np.matmul(b, half, out=prod)
    return out
