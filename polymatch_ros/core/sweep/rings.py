"""Twisted states on a ring: the loop of rotations O_1 -> O_2 -> ... -> O_N -> O_1.

On a ring graph (``core.graph``, ``{ring: k}``: agent i hears i +- 1 .. i +- k) the
equilibria of (A-2) that are not consensus are *twisted*: each step R_j = O_j^T O_{j+1}
(indices mod N) turns by the same angle.  With R_j = exp(A_j), A_j the principal
logarithm (skew, eigenvalues +-i phi with 0 <= phi < pi), the loop made of the geodesic
steps t -> O_j exp(t A_j) is a closed curve in SO(d), and

- d = 2: O_j = R(theta_j); the winding number q = sum_j wrap(theta_{j+1} - theta_j) / 2 pi
  (an integer: the phases turn q times around the ring; Kuramoto's q-twisted state
  theta_j = 2 pi q j / N is a twisted equilibrium of the first-order model on the ring);
- every d: the total turn T = sum_j |A_j|_F / (2 pi sqrt 2) (full turns; |q| in d = 2, and
  |q| for a q-twist in one plane in any d);
- every d: the loop's class in the fundamental group of SO(d), Z for d = 2 and Z2 for
  d >= 3, read off the spin lift: the steps lift to the spin group as exp(A_j / 4
  contracted with gamma_a gamma_b) (``spin_lift``; gamma_a generate the Clifford algebra,
  gamma_a gamma_b + gamma_b gamma_a = 2 delta_ab) and their ordered product is +1 or -1
  times the identity; -1 iff the loop is not contractible (in d = 2: (-1)^q).

A flow that keeps every step's angle below pi moves the loop continuously, so it cannot
change its class: in d >= 3 a loop of odd q cannot unwind to consensus (class +1), a
loop of even q may.  ``twisted_rotations`` builds the q-twisted states themselves.
"""

from dataclasses import dataclass

import numpy as np

#: a step turning by more than this is (nearly) a half-turn: its logarithm is not unique
HALF_TURN_MARGIN = 1e-6


def principal_logs(r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(A, phi_max): A = log R (skew, eigen-angles in [0, pi)) and the largest angle, for a
    stack of rotations (..., d, d).

    R is normal, so its symmetric part C = (R + R^T)/2 (eigenvalues cos phi) commutes with
    its skew part K = (R - R^T)/2, and on each eigenspace of C the logarithm is
    (phi / sin phi) K: A = f(C) K with f(c) = arccos(c) / sqrt(1 - c^2), f(C) from one
    symmetric eigendecomposition.  No branch cut short of phi = pi.
    """
    c_mat = 0.5 * (r + np.swapaxes(r, -1, -2))
    k_mat = 0.5 * (r - np.swapaxes(r, -1, -2))
    cos, vec = np.linalg.eigh(c_mat)
    phi = np.arccos(np.clip(cos, -1.0, 1.0))
    sin = np.sin(phi)
    small = phi < 1e-4
    ratio = np.where(small, 1.0 + phi * phi / 6.0, phi / np.where(small, 1.0, sin))
    f_mat = np.einsum("...ik,...k,...jk->...ij", vec, ratio, vec)
    return f_mat @ k_mat, phi.max(axis=-1)


def gamma_matrices(d: int) -> np.ndarray:
    """(d, s, s) generators of the Clifford algebra of R^d (Jordan-Wigner; s = 2^(d // 2))."""
    sx = np.array([[0, 1], [1, 0]], dtype=complex)
    sy = np.array([[0, -1j], [1j, 0]])
    sz = np.diag([1.0 + 0j, -1.0])
    m = max(d // 2, 1)

    def kron(*parts: np.ndarray) -> np.ndarray:
        out = np.ones((1, 1), dtype=complex)
        for p in parts:
            out = np.kron(out, p)
        return out

    eye = np.eye(2, dtype=complex)
    gammas = []
    for j in range(m):
        for s in (sx, sy):
            gammas.append(kron(*([sz] * j + [s] + [eye] * (m - j - 1))))
    if d % 2:
        gammas.append(kron(*([sz] * m)))
    return np.array(gammas[:d])


def spin_lift(a: np.ndarray) -> np.ndarray:
    """exp(1/4 sum_ab A_ab gamma_a gamma_b) for skew A (..., d, d): the spin element over
    exp(A) (conjugation by it turns gamma(v) into gamma(exp(A) v)), reached along exp(t A)."""
    d = a.shape[-1]
    g = gamma_matrices(d)
    bivector = 0.25 * np.einsum("...ab,aij,bjk->...ik", a, g, g)     # anti-Hermitian
    w, u = np.linalg.eigh(1j * bivector)                            # Hermitian: i B = U w U^H
    return np.einsum("...ik,...k,...jk->...ij", u, np.exp(-1j * w), u.conj())


@dataclass(frozen=True)
class RingMeasures:
    """Per ensemble (arrays of length B) the loop of its rotations around the ring."""

    winding: np.ndarray       # d = 2: the winding number q (signed); nan for d >= 3
    turn: np.ndarray          # total turn T in full turns (|q| for a planar q-twist)
    loop_class: np.ndarray    # +1: contractible loop, -1: not (d = 2: (-1)^q)
    step_spread: np.ndarray   # max_j |A_j| - min_j |A_j| over the steps, radians
    step_max: np.ndarray      # the largest step angle (near pi: the class is ill-defined)


def ring_measures(mats: np.ndarray) -> RingMeasures:
    """``RingMeasures`` of rotations (B, N, d, d), agents in ring order (module doc)."""
    d = mats.shape[-1]
    steps = np.swapaxes(mats, -1, -2) @ np.roll(mats, -1, axis=1)     # R_j = O_j^T O_{j+1}
    logs, step_max = principal_logs(steps)
    angles = np.linalg.norm(logs, axis=(-2, -1)) / np.sqrt(2.0)        # (B, N)
    lifts = spin_lift(logs)
    product = lifts[:, 0]
    for j in range(1, lifts.shape[1]):
        product = product @ lifts[:, j]
    loop_class = np.sign(np.trace(product, axis1=-2, axis2=-1).real)
    winding = np.full(len(mats), np.nan)
    if d == 2:
        winding = np.rint(logs[:, :, 1, 0].sum(axis=1) / (2 * np.pi)) + 0.0    # no -0
    return RingMeasures(winding, angles.sum(axis=1) / (2 * np.pi), loop_class,
                        angles.max(axis=1) - angles.min(axis=1), step_max.max(axis=1))


def twisted_rotations(d: int, n: int, q: float, plane: tuple[int, int] = (0, 1)) -> np.ndarray:
    """(N, d, d): O_j turns by 2 pi q j / N in one coordinate plane (the q-twisted state)."""
    angles = 2.0 * np.pi * q * np.arange(n) / n
    out = np.repeat(np.eye(d)[None], n, axis=0)
    i, k = plane
    out[:, i, i] = out[:, k, k] = np.cos(angles)
    out[:, k, i] = np.sin(angles)
    out[:, i, k] = -np.sin(angles)
    return out


def perturbed(mats: np.ndarray, size: float, rng: np.random.Generator) -> np.ndarray:
    """O_j exp(size X_j): X_j random skew with |X_j|_F = sqrt 2 (a turn of ``size`` rad)."""
    from scipy.linalg import expm

    d = mats.shape[-1]
    g = rng.standard_normal(mats.shape)
    x = g - np.swapaxes(g, -1, -2)
    x *= np.sqrt(2.0) / np.linalg.norm(x, axis=(-2, -1))[..., None, None]
    return mats @ np.array([expm(size * xi) for xi in x.reshape(-1, d, d)]).reshape(mats.shape)
