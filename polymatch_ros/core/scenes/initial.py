"""Initial states of a scene's groups: seeded random draws or explicit values, validated.

Centroids in a box, a ball or at given points; rotations uniform (Haar), within an angle
of a base rotation, or given (angles, rotation vectors, matrices); scales for similar
ensembles (F-1); centroid and angular velocities for the second-order model (A-1).
"""

from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import SceneError
from .checks import Map, describe, matrix_rows, number, vector
from .limits import MAX_LENGTH, MIN_SIZE

if TYPE_CHECKING:
    from ..so import RotationGroup


def centroids(raw: object, path: str, dim: int, count: int,
              rng: np.random.Generator) -> np.ndarray:
    if isinstance(raw, dict) and len(raw) == 1:
        (kind, val), = raw.items()
        p = f"{path}.{kind}"
        if kind == "box":
            pair = isinstance(val, list) and len(val) == 2 and not isinstance(val[0], list)
            b = np.tile(vector(val, p, 2, bound=MAX_LENGTH), (dim, 1)) if pair else \
                matrix_rows(val, p, dim, 2, bound=MAX_LENGTH)
            if np.any(b[:, 1] < b[:, 0]):
                raise SceneError(f"{p}: expected [lo, hi] or {dim} pairs [lo, hi] with lo <= hi")
            return b[:, 0] + (b[:, 1] - b[:, 0]) * rng.random((count, dim))
        if kind == "points":
            return matrix_rows(val, p, count, dim, bound=MAX_LENGTH)
        if kind == "normal":
            nm = Map(val, p, ("mean", "std"))
            mean = vector(nm.raw("mean", [0.0] * dim), nm.at("mean"), dim, bound=MAX_LENGTH)
            std = nm.number("std", 1.0, minimum=0, maximum=MAX_LENGTH / 10)
            return mean + std * rng.standard_normal((count, dim))
        if kind == "at":
            return np.tile(vector(val, p, dim, bound=MAX_LENGTH), (count, 1))
    raise SceneError(f"{path}: expected one of {{box: ...}}, {{points: ...}}, {{normal: ...}}, "
                     f"{{at: [...]}}, got {describe(raw)}")


def base_rotation(raw: object, path: str, dim: int) -> np.ndarray:
    if raw is None or (isinstance(raw, str) and raw == "identity"):
        return np.eye(dim)
    if isinstance(raw, dict) and len(raw) == 1:
        (kind, val), = raw.items()
        p = f"{path}.{kind}"
        if kind == "angle":
            if dim != 2:
                raise SceneError(f"{p}: an angle defines a rotation only for dimension 2")
            a = number(val, p)
            return np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
        if kind == "rotvec":
            from scipy.spatial.transform import Rotation
            if dim != 3:
                raise SceneError(f"{p}: a rotation vector defines a rotation only for dimension 3")
            return Rotation.from_rotvec(vector(val, p, 3)).as_matrix()
        if kind == "matrix":
            return check_rotation(matrix_rows(val, p, dim, dim), p)
    raise SceneError(f"{path}: expected identity, {{angle: a}}, {{rotvec: [...]}} or "
                     f"{{matrix: [[...]]}}, got {describe(raw)}")


def check_rotation(m: np.ndarray, path: str) -> np.ndarray:
    err = np.abs(m.T @ m - np.eye(len(m))).max()
    if err > 1e-9:
        raise SceneError(f"{path}: not orthogonal (|O^T O - I| = {err:.3g})")
    if np.linalg.det(m) < 0:
        raise SceneError(f"{path}: a reflection (det -1), not a rotation")
    return m


def random_rotation_within(dim: int, count: int, angle: float,
                           rng: np.random.Generator) -> np.ndarray:
    """Rotations exp(theta A), A a random unit-spectral-norm skew matrix, theta ~ U[0, angle]."""
    out = np.empty((count, dim, dim))
    for start in range(0, count, 4096):             # batched: the draws match one at a time
        n = min(4096, count - start)
        a = np.empty((n, dim, dim))
        theta = np.empty(n)
        for i in range(n):
            g = rng.standard_normal((dim, dim))
            a[i] = g - g.T
            theta[i] = rng.uniform(0.0, angle)
        a /= np.linalg.norm(a, 2, axis=(1, 2))[:, None, None]
        out[start:start + n] = _skew_exp(theta[:, None, None] * a)
    return out


def _skew_exp(w: np.ndarray) -> np.ndarray:
    """exp of skew matrices (n, d, d): closed forms in d = 2 (cos, sin) and d = 3
    (Rodrigues, scipy's Rotation), scipy's expm (one Pade evaluation a matrix) above."""
    dim = w.shape[-1]
    if dim == 2:
        angle = w[:, 1, 0]
        c, s = np.cos(angle), np.sin(angle)
        return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)
    if dim == 3:
        from scipy.spatial.transform import Rotation
        return Rotation.from_rotvec(np.stack([w[:, 2, 1], w[:, 0, 2], w[:, 1, 0]], -1)).as_matrix()
    from scipy.linalg import expm
    return expm(w)


def rotations(raw: object, path: str, dim: int, count: int,
              rng: np.random.Generator) -> np.ndarray:
    if isinstance(raw, str) and raw == "uniform":
        if dim == 2:
            a = rng.uniform(-np.pi, np.pi, count)
            return np.stack([np.stack([np.cos(a), -np.sin(a)], -1),
                             np.stack([np.sin(a), np.cos(a)], -1)], -2)
        if dim == 3:
            from scipy.spatial.transform import Rotation
            return Rotation.random(count, random_state=rng).as_matrix().reshape(count, 3, 3)
        from scipy.stats import special_ortho_group  # slow to import: only when needed
        return special_ortho_group.rvs(dim, size=count, random_state=rng).reshape(count, dim, dim)
    if isinstance(raw, str) and raw == "identity":
        return np.repeat(np.eye(dim)[None], count, axis=0)
    if isinstance(raw, dict):
        if "within" in raw:
            rm = Map(raw, path, ("within", "base"))
            angle = rm.number("within", minimum=0, maximum=1e6)
            base = base_rotation(rm.raw("base"), rm.at("base"), dim)
            return random_rotation_within(dim, count, angle, rng) @ base
        if len(raw) == 1:
            (kind, val), = raw.items()
            p = f"{path}.{kind}"
            if kind == "angles":
                if dim != 2:
                    raise SceneError(f"{p}: angles define rotations only for dimension 2")
                a = vector(val, p, count, bound=1e6)
                return np.stack([np.stack([np.cos(a), -np.sin(a)], -1),
                                 np.stack([np.sin(a), np.cos(a)], -1)], -2)
            if kind == "rotvecs":
                from scipy.spatial.transform import Rotation
                if dim != 3:
                    raise SceneError(f"{p}: rotation vectors define rotations only for "
                                     f"dimension 3")
                return Rotation.from_rotvec(matrix_rows(val, p, count, 3, bound=1e6)).as_matrix()
            if kind == "matrices":
                if not isinstance(val, list) or len(val) != count:
                    raise SceneError(f"{p}: expected {count} matrices, got {describe(val)}")
                return np.array([check_rotation(matrix_rows(m, f"{p}[{i}]", dim, dim), f"{p}[{i}]")
                                 for i, m in enumerate(val)])
    raise SceneError(f"{path}: expected uniform, identity, {{within: angle, base: ...}}, "
                     f"{{angles: [...]}}, {{rotvecs: [...]}} or {{matrices: [...]}}, "
                     f"got {describe(raw)}")


def scales(raw: object, path: str, count: int, rng: np.random.Generator) -> np.ndarray:
    """Scales s_i of a similar ensemble (F-1), each within [MIN_SIZE, 1 / MIN_SIZE]."""
    usage = "expected a list, {uniform: [lo, hi]} or {log_uniform: [lo, hi]}"
    lo_hi = (MIN_SIZE, 1.0 / MIN_SIZE)
    if isinstance(raw, list):
        s = vector(raw, path, count)
        p = path
    elif isinstance(raw, dict) and len(raw) == 1 and next(iter(raw)) in ("uniform", "log_uniform"):
        (kind, val), = raw.items()
        p = f"{path}.{kind}"
        b = vector(val, p, 2)
        if not 0 < b[0] <= b[1]:
            raise SceneError(f"{p}: expected [lo, hi] with 0 < lo <= hi")
        s = b
    else:
        raise SceneError(f"{path}: {usage}, got {describe(raw)}")
    if not np.all((s >= lo_hi[0]) & (s <= lo_hi[1])):
        raise SceneError(f"{p}: scales must lie in [{lo_hi[0]:g}, {lo_hi[1]:g}] (beyond, the F-1 "
                         f"torque weights s_k/s_i are not representable)")
    if isinstance(raw, list):
        return s
    if kind == "uniform":
        return rng.uniform(b[0], b[1], count)
    return np.exp(rng.uniform(np.log(b[0]), np.log(b[1]), count))


def velocities(raw: object, path: str, dim: int, count: int,
               rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    vm = Map(raw, path, ("centroid", "angular"))
    v = random_vectors(vm.raw("centroid", "zero"), vm.at("centroid"), (count, dim), rng)
    k = dim * (dim - 1) // 2
    comps = random_vectors(vm.raw("angular", "zero"), vm.at("angular"), (count, k), rng)
    return v, skew_from_components(comps, dim)


def random_vectors(raw: object, path: str, shape: tuple[int, int],
                   rng: np.random.Generator) -> np.ndarray:
    if (isinstance(raw, str) and raw == "zero") or (type(raw) in (int, float) and raw == 0):
        return np.zeros(shape)
    if isinstance(raw, dict) and len(raw) == 1:
        (kind, val), = raw.items()
        if kind == "normal":
            std = number(val, f"{path}.normal", minimum=0, maximum=MAX_LENGTH / 10)
            return std * rng.standard_normal(shape)
        if kind == "values":
            return matrix_rows(val, f"{path}.values", *shape, bound=MAX_LENGTH)
    raise SceneError(f"{path}: expected zero, {{normal: std}} or {{values: [[...], ...]}}, "
                     f"got {describe(raw)}")


def explicit_vectors(values: list[Any], path: str, key: str, dim: int,
                     order: int) -> np.ndarray | None:
    if all(v is None for v in values):
        return None
    return np.array([np.zeros(dim) if v is None else
                     vector(v, f"{path}[{i}].{key}", dim, bound=MAX_LENGTH)
                     for i, v in enumerate(values)])


def explicit_omegas(values: list[Any], path: str, dim: int, order: int,
                    rotations: "RotationGroup") -> Any:
    if all(v is None for v in values):
        return None
    k = dim * (dim - 1) // 2
    rows = [np.zeros(k) if v is None else
            vector(v, f"{path}[{i}].angular_velocity", k, bound=MAX_LENGTH)
            for i, v in enumerate(values)]
    w = skew_from_components(np.array(rows), dim)
    return rotations.algebra_from_skew(w)


def skew_from_components(comps: Any, dim: int) -> np.ndarray:
    """(N, d(d-1)/2) components -> (N, d, d) skew matrices.

    For d = 3 the components are the angular-velocity vector (w_x, w_y, w_z);
    for d = 2 the single component is the rate about z; otherwise they are the
    strictly lower-triangular entries W[j, i] (i < j) in row-major order.
    """
    comps = np.asarray(comps, dtype=float)
    w = np.zeros((comps.shape[0], dim, dim))
    if dim == 3:
        x, y, z = comps.T
        w[:, 0, 1], w[:, 0, 2], w[:, 1, 2] = -z, y, -x
        w[:, 1, 0], w[:, 2, 0], w[:, 2, 1] = z, -y, x
        return w
    iu = np.triu_indices(dim, 1)
    w[:, iu[1], iu[0]] = comps
    w[:, iu[0], iu[1]] = -comps
    return w
