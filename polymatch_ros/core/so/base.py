"""The interface of the batched SO(d) representations, and the polar factor they share."""

import functools
import math
import sys
import threading
from collections.abc import Sequence
from typing import Any

import numpy as np

#: a batch of N rotations, or of N so(d) elements, in a representation's own layout
Array = np.ndarray
#: S = sum_k w_k O_k: a complex number for angles, a (d, d) matrix otherwise; on a graph one
#: field per agent, S_i = sum_k w_ik O_k (``neighbour_fields``), in the rotations' own layout
MeanField = complex | np.ndarray
#: rows of a batch: an index, a slice, or a list or array of indices
RowIndex = int | slice | Sequence[int] | np.ndarray
#: a scipy.sparse (n, N) matrix of weights w_ik (scipy ships no type information)
SparseWeights = Any


class RotationGroup:
    """Interface shared by the batched SO(d) representations."""

    dim: int = 0
    name: str = "abstract"
    #: which map ``retract`` uses: "exp" or "cayley"
    retraction: str = "exp"
    #: True when rotations commute (SO(2)): dpsi_inv is the identity
    abelian: bool = False

    # -- construction and conversion -------------------------------------
    def identity(self, n: int) -> Array:
        raise NotImplementedError

    def from_matrices(self, mats: np.ndarray) -> Array:
        """(N, d, d) rotation matrices -> group array."""
        raise NotImplementedError

    def to_matrices(self, g: Array) -> np.ndarray:
        """Group array -> (N, d, d) rotation matrices."""
        raise NotImplementedError

    def flat(self, g: Array) -> np.ndarray:
        """(N, d*d) row-major matrix entries; Frobenius distances are Euclidean here."""
        return self.to_matrices(g).reshape(self.count(g), -1)

    def count(self, g: Array) -> int:
        raise NotImplementedError

    def take(self, g: Array, idx: RowIndex) -> Array:
        raise NotImplementedError

    def put(self, g: Array, idx: RowIndex, values: Array) -> None:
        """Write rows ``idx`` of ``g`` in place."""
        raise NotImplementedError

    def concat(self, parts: Sequence[Array]) -> Array:
        raise NotImplementedError

    def rotate(self, g: Array, r: np.ndarray) -> np.ndarray:
        """Apply every rotation to one vector r (d,): returns (N, d)."""
        raise NotImplementedError

    # -- Lie algebra -----------------------------------------------------
    def algebra_zeros(self, n: int) -> Array:
        raise NotImplementedError

    def algebra_take(self, a: Array, idx: RowIndex) -> Array:
        raise NotImplementedError

    def algebra_concat(self, parts: Sequence[Array]) -> Array:
        raise NotImplementedError

    def algebra_from_skew(self, w: np.ndarray) -> Array:
        """(N, d, d) skew matrices -> algebra array."""
        raise NotImplementedError

    def algebra_to_skew(self, a: Array) -> np.ndarray:
        """Algebra array -> (N, d, d) skew matrices."""
        raise NotImplementedError

    def algebra_sq_norm(self, a: Array) -> np.ndarray:
        """Squared Frobenius norm of hat(a), per rotation: (N,)."""
        raise NotImplementedError

    def algebra_scale_rows(self, a: Array, c: np.ndarray) -> Array:
        """Multiply row i of an algebra array by c[i]."""
        raise NotImplementedError

    # -- maps the integrators use ------------------------------------------
    def retract(self, xi: Array, g: Array) -> Array:
        """psi(xi) O for each rotation; psi is exp or Cayley."""
        raise NotImplementedError

    def retract_each(self, xis: np.ndarray, g: Array) -> list[Array]:
        """[psi(xi) O for xi in xis]: xis stacks algebra arrays along a leading axis."""
        return [self.retract(xi, g) for xi in xis]

    def dpsi_inv(self, xi: Array, a: Array) -> Array:
        """Inverse right-trivialised differential of psi at xi, applied to a."""
        raise NotImplementedError

    def mean_field(self, g: Array, weights: np.ndarray | None = None) -> MeanField:
        """S = sum_k w_k O_k (representation-specific)."""
        raise NotImplementedError

    def neighbour_fields(self, g: Array, weights: SparseWeights) -> Array:
        """S_i = sum_k w_ik O_k for every row i of a sparse (n, N) matrix w: one product w @ O.

        The per-agent fields of a communication graph (``core.graph``), O(|E| d^2).
        """
        raise NotImplementedError

    def coupling(self, g: Array, s: MeanField) -> Array:
        """The skew kernel S O_i^T - O_i S^T of the Lohe torque (A-1, A-2), as an algebra array.

        ``s`` is one mean field for all rows or one field per row (``neighbour_fields``).
        Only ``model.lohe_torque`` calls it: that is where gains and F-1 weights are applied,
        in place (the result is a new array the caller owns, as ``algebra_scale_rows``'s).
        """
        raise NotImplementedError

    # -- embedding-space operations (projection baselines) ----------------
    def tangent(self, a: Array, g: Array) -> Array:
        """hat(a) O in the embedding space (same layout as the group array)."""
        raise NotImplementedError

    def project(self, g: Array) -> Array:
        """Nearest rotation (polar factor) of each near-orthogonal matrix."""
        raise NotImplementedError



class RowsFirstGroup(RotationGroup):
    """A representation whose group and algebra arrays hold rotation i in row i (axis 0).

    Angles (N,) and matrices (N, d, d) share this layout, and with it the row bookkeeping.
    """

    def count(self, g: Array) -> int:
        return g.shape[0]

    def take(self, g: Array, idx: RowIndex) -> Array:
        return g[idx]

    def put(self, g: Array, idx: RowIndex, values: Array) -> None:
        g[idx] = values

    def concat(self, parts: Sequence[Array]) -> Array:
        return np.concatenate(parts, axis=0)

    def algebra_take(self, a: Array, idx: RowIndex) -> Array:
        return a[idx]

    def algebra_concat(self, parts: Sequence[Array]) -> Array:
        return np.concatenate(parts, axis=0)

class ComponentAlgebra:
    """A mixin for algebra arrays that hold component k of every agent in row k: (rows, N).

    SO(3) (3 rows) and SO(4) (6 rows) keep their Lie algebra so, structure of arrays."""

    algebra_rows = 0

    def algebra_zeros(self, n: int) -> Array:
        return np.zeros((self.algebra_rows, n))

    def algebra_take(self, a: Array, idx: RowIndex) -> Array:
        return a[:, idx]

    def algebra_concat(self, parts: Sequence[Array]) -> Array:
        return np.concatenate(parts, axis=1)


#: multiply-adds below which OpenBLAS runs a product on one thread (2^18); a threaded product
#: of a long, thin matrix stalls whenever the machine's cores are busy
ONE_THREAD_PRODUCT = 1 << 18


#: reused temporaries by name, each of the last shape asked for, one set per thread (``scratch``)
_SCRATCH = threading.local()


def scratch(name: str, shape: tuple) -> np.ndarray:
    """A kept float array of ``shape`` for a temporary that never leaves the call using it.

    A large temporary allocated afresh on every call costs page faults (the allocator hands
    freed blocks of megabytes back to the system) that can exceed the arithmetic done on it;
    one kept array per name (and thread) avoids them.  Contents are undefined; never return it.
    """
    kept = _SCRATCH.__dict__
    buf = kept.get(name)
    if buf is None or buf.shape != shape:
        buf = kept[name] = np.empty(shape)
    return buf


#: arrays ``recycled`` keeps, least recently handed out first, one list per thread
_RECYCLED = threading.local()
#: how many arrays ``recycled`` keeps per thread (a step of rkmk4 holds about ten at once)
RECYCLED_ARRAYS = 16
#: arrays smaller than this (bytes) are simply allocated: the allocator reuses them cheaply
RECYCLED_MIN_BYTES = 1 << 17


def _references(kept: list, k: int) -> int:
    return sys.getrefcount(kept[k])


#: what ``_references`` counts for an array that only the kept list refers to
_UNREFERENCED = _references([np.empty(0)], 0)


def recycled(shape: tuple) -> np.ndarray:
    """A float array of ``shape`` for a result that leaves the call, its memory reused.

    Like ``scratch`` it spares the page faults of a large fresh array, but the caller may keep
    the result as long as it likes: a kept array is handed out again only once nothing else
    refers to it (its reference count says so; a view counts, as it refers to its base),
    which is how numpy itself reuses temporaries.  Contents are undefined.
    """
    if 8 * math.prod(shape) < RECYCLED_MIN_BYTES:
        return np.empty(shape)
    kept = _RECYCLED.__dict__.setdefault("arrays", [])
    for k in range(len(kept)):
        if kept[k].shape == shape and _references(kept, k) == _UNREFERENCED:
            kept.append(kept.pop(k))
            return kept[-1]
    if len(kept) >= RECYCLED_ARRAYS:
        held = [k for k in range(len(kept)) if _references(kept, k) > _UNREFERENCED]
        kept.pop(held[0] if held else 0)
    buf = np.empty(shape)
    kept.append(buf)
    return buf


#: bytes of one array's rows that a row-blocked computation takes at a time (``row_blocks``)
ROW_BLOCK_BYTES = 1 << 20


def row_blocks(shape: tuple) -> tuple[int, list[slice]]:
    """(rows per block, the row slices) of an array of ``shape``, each block ROW_BLOCK_BYTES.

    A computation of several steps on a block at a time keeps its temporaries in the CPU
    caches (a block of each fits, where whole arrays of megabytes do not).
    """
    row_bytes = 8 * math.prod(shape[1:])
    rows = max(1, min(shape[0], ROW_BLOCK_BYTES // max(row_bytes, 1)))
    return rows, [slice(s, min(s + rows, shape[0])) for s in range(0, shape[0], rows)]


def rows_product(a: np.ndarray, b: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """a @ b for a long (n, k) a and a small (k, m) b, in row blocks each on one thread."""
    rows = max(1, ONE_THREAD_PRODUCT // (a.shape[1] * b.shape[1]))
    if a.shape[0] <= rows:
        return np.matmul(a, b, out=out)
    out = np.empty((a.shape[0], b.shape[1])) if out is None else out
    for start in range(0, a.shape[0], rows):
        np.matmul(a[start:start + rows], b, out=out[start:start + rows])
    return out


@functools.lru_cache(maxsize=64)
def constant_weights(n: int, value: float = 1.0) -> np.ndarray:
    """A read-only (n,) array of ``value``: the weights of a plain row sum or mean, made once."""
    w = np.full(n, value)
    w.flags.writeable = False
    return w


def row_sum(a: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
    """sum_k w_k a[k] of a long (n, k) a, in row blocks each on one thread (``rows_product``).

    A single long vector-matrix product is spread by OpenBLAS over threads that stall on a
    busy machine.
    """
    rows = max(1, ONE_THREAD_PRODUCT // a.shape[1])
    w = constant_weights(a.shape[0]) if weights is None else np.asarray(weights, dtype=float)
    if a.shape[0] <= rows:
        return w @ a
    out = w[:rows] @ a[:rows]
    for start in range(rows, a.shape[0], rows):
        out += w[start:start + rows] @ a[start:start + rows]
    return out


def polar_newton_schulz(mats: np.ndarray, tol: float = 1e-15, max_iter: int = 12) -> np.ndarray:
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
