"""A small library of polytopes, each a centred reference vertex set r_a with edges.

The paper identifies a polytope with its vertex set {x_a} and writes every
member of a congruent ensemble as x^i_a = xbar^i + O^i r_a with sum_a r_a = 0
(Section 3).  ``Shape.vertices`` is that r_a, scaled so the circumradius is
``size``.
"""

from collections.abc import Callable
from dataclasses import dataclass
from itertools import combinations, product
from typing import Any

import numpy as np

from ..errors import SceneError
from .checks import describe, matrix_rows, number
from .limits import MAX_LENGTH, MAX_VERTICES, count_text, shape_vertex_count


@dataclass(frozen=True)
class Shape:
    """A centred reference polytope: vertices (n, k) and edges [(a, b), ...]."""

    name: str
    vertices: np.ndarray
    edges: tuple

    @property
    def dim(self) -> int:
        return self.vertices.shape[1]

    @property
    def circumradius(self) -> float:
        return float(np.max(np.linalg.norm(self.vertices, axis=1)))

    @property
    def rank(self) -> int:
        """Dimension of span{r_a}; the paper's Lemma 3.2 assumes it equals d."""
        return int(np.linalg.matrix_rank(self.vertices, tol=1e-9 * max(self.circumradius, 1e-300)))

    def embedded(self, dim: int) -> "Shape":
        """The same shape in R^dim (zero-padded); a triangle becomes a triangle in R^3."""
        if dim < self.dim:
            raise SceneError(f"shape {self.name!r} lives in R^{self.dim}, the scene in R^{dim}")
        pad = np.zeros((self.vertices.shape[0], dim - self.dim))
        return Shape(self.name, np.hstack([self.vertices, pad]), self.edges)

    def scaled(self, size: float) -> "Shape":
        r = self.circumradius
        return Shape(self.name, self.vertices * (size / r), self.edges)


def _centred(vertices: Any) -> np.ndarray:
    v = np.asarray(vertices, dtype=float)
    return v - v.mean(axis=0)


def polygon(n: int, path: str = "shape") -> Shape:
    """Regular n-gon in R^2, circumradius 1, first vertex on the +y axis."""
    if n < 3:
        raise SceneError(f"{path}.polygon: a polygon needs at least 3 sides, got {n}")
    ang = np.pi / 2 + 2 * np.pi * np.arange(n) / n
    v = np.stack([np.cos(ang), np.sin(ang)], axis=1)
    return Shape(f"polygon{n}", _centred(v), tuple((a, (a + 1) % n) for a in range(n)))


def simplex(k: int, path: str = "shape") -> Shape:
    """Regular k-simplex in R^k (k + 1 vertices), circumradius 1."""
    if k < 1:
        raise SceneError(f"{path}.simplex: dimension must be >= 1, got {k}")
    e = np.eye(k + 1) - 1.0 / (k + 1)        # centred standard basis of R^{k+1}
    _, _, vt = np.linalg.svd(e)
    v = e @ vt[:k].T                         # coordinates in the hyperplane sum = 0
    v /= np.max(np.linalg.norm(v, axis=1))
    return Shape(f"simplex{k}", _centred(v), tuple(combinations(range(k + 1), 2)))


def hypercube(k: int, path: str = "shape") -> Shape:
    """Cube [-1, 1]^k scaled to circumradius 1 (square for k = 2); edges flip one coordinate."""
    v = np.array(list(product((-1.0, 1.0), repeat=k)))
    n = len(v)
    edges = tuple((a, a ^ (1 << bit)) for a in range(n) for bit in range(k) if a < a ^ (1 << bit))
    return Shape(f"hypercube{k}", v / np.sqrt(k), tuple(sorted(edges)))


def cross_polytope(k: int, path: str = "shape") -> Shape:
    """The 2k points +-e_i in R^k (octahedron for k = 3)."""
    v = np.vstack([np.eye(k), -np.eye(k)])
    edges = tuple((a, b) for a, b in combinations(range(2 * k), 2) if abs(a - b) != k)
    return Shape(f"cross_polytope{k}", v, edges)


_NAMED: dict[str, Callable[[], Shape]] = {
    "triangle": lambda: polygon(3),
    "square": lambda: hypercube(2),
    "pentagon": lambda: polygon(5),
    "hexagon": lambda: polygon(6),
    "tetrahedron": lambda: simplex(3),
    "cube": lambda: hypercube(3),
    "octahedron": lambda: cross_polytope(3),
}

_FAMILIES: dict[str, Callable[[int, str], Shape]] = {"polygon": polygon, "simplex": simplex,
             "hypercube": hypercube, "cross_polytope": cross_polytope}


def shape_names() -> list[str]:
    return (sorted(_NAMED) + [f"{{{k}: n}}" for k in sorted(_FAMILIES)]
            + ["{vertices: [...], edges: [...]}"])


def make_shape(spec: object, path: str = "shape", max_dim: int | None = None) -> Shape:
    """Build a Shape from a scene entry.

    ``spec`` is a name ("triangle", "tetrahedron", ...), ``{polygon: 5}``,
    ``{simplex: 4}``, ``{hypercube: 3}``, ``{cross_polytope: 4}``, or
    ``{vertices: [[...], ...], edges: [[0, 1], ...]}`` (edges optional).  Sizes are
    checked (MAX_VERTICES, ``max_dim``) before anything is built.
    """
    if isinstance(spec, str):
        if spec not in _NAMED:
            raise SceneError(f"{path}: unknown shape {spec!r}; known: {', '.join(shape_names())}")
        shape = _NAMED[spec]()
        return Shape(spec, shape.vertices, shape.edges)
    if not isinstance(spec, dict) or not spec:
        raise SceneError(f"{path}: expected a shape name or a mapping, got {describe(spec)}")
    if "vertices" in spec:
        return _custom_shape(spec, path, max_dim)
    if len(spec) != 1:
        raise SceneError(f"{path}: expected one of {sorted(_FAMILIES)} or 'vertices', "
                         f"got keys {sorted(map(str, spec))}")
    (family, n), = spec.items()
    if family not in _FAMILIES:
        raise SceneError(f"{path}: unknown shape family {family!r}; known: "
                         f"{', '.join(sorted(_FAMILIES))}, vertices")
    p = f"{path}.{family}"
    n = number(n, p, integer=True, minimum=3 if family == "polygon" else 1)
    shape_dim = 2 if family == "polygon" else n
    if max_dim is not None and shape_dim > max_dim:
        raise SceneError(f"{p}: a {family} of dimension {shape_dim} does not fit the scene's "
                         f"dimension {max_dim}")
    vertices, _ = shape_vertex_count(family, n)
    if vertices > MAX_VERTICES:
        raise SceneError(f"{p}: {count_text(vertices)} vertices; a polytope may have at most "
                         f"{MAX_VERTICES}")
    return _FAMILIES[family](n, path)


def _custom_shape(spec: dict[Any, Any], path: str, max_dim: int | None) -> Shape:
    extra = set(spec) - {"vertices", "edges", "name"}
    if extra:
        raise SceneError(f"{path}.{sorted(map(str, extra))[0]}: unknown key")
    v = check_vertex_array(spec["vertices"], f"{path}.vertices", max_dim=max_dim)
    n = v.shape[0]
    edges = spec.get("edges")
    if edges is None:
        edges = tuple((a, (a + 1) % n) for a in range(n)) if n > 2 else ((0, 1),)
    else:
        rows = len(edges) if isinstance(edges, list) else 0
        pairs = matrix_rows(edges, f"{path}.edges", rows, 2)
        if np.any(pairs != np.round(pairs)) or np.any(pairs < 0) or np.any(pairs >= n):
            raise SceneError(f"{path}.edges: expected pairs [a, b] of vertex indices 0..{n - 1}")
        edges = tuple((int(a), int(b)) for a, b in pairs)
    name = spec.get("name", "custom")
    if not isinstance(name, str):
        raise SceneError(f"{path}.name: expected text, got {describe(name)}")
    shape = Shape(name, _centred(v), edges)
    check_distinct_vertices(shape.vertices, f"{path}.vertices")
    return shape


def check_vertex_array(value: object, path: str, dim: int | None = None, *,
                       max_dim: int | None = None) -> np.ndarray:
    """A finite (n, k) array, 2 <= n <= MAX_VERTICES, k == dim, k <= max_dim; or SceneError."""
    want = "a list of vertices, each a list of coordinates of the same length"
    if not isinstance(value, (list, np.ndarray)) or len(value) == 0:
        raise SceneError(f"{path}: expected {want}, got {describe(value)}")
    rows = value.tolist() if isinstance(value, np.ndarray) else value
    for a, row in enumerate(rows):
        if not isinstance(row, (list, tuple)) or not row:
            raise SceneError(f"{path}[{a}]: expected a list of coordinates, got {describe(row)}")
        if len(row) != len(rows[0]):
            raise SceneError(f"{path}[{a}]: vertex {a} has {len(row)} coordinate(s), vertex 0 "
                             f"has {len(rows[0])}")
    k = len(rows[0])
    if (dim is not None and k != dim) or (max_dim is not None and k > max_dim):
        raise SceneError(f"{path}: vertices have {k} coordinates, the scene has dimension "
                         f"{dim or max_dim}")
    if len(rows) > MAX_VERTICES:
        raise SceneError(f"{path}: {len(rows)} vertices; a polytope may have at most "
                         f"{MAX_VERTICES}")
    v = matrix_rows(rows, path, len(rows), len(rows[0]), bound=MAX_LENGTH)
    if v.shape[0] < 2:
        raise SceneError(f"{path}: a polytope needs at least 2 vertices, got {v.shape[0]}")
    return v


def check_distinct_vertices(v: np.ndarray, path: str,
                            error: Callable[[str], Exception] = SceneError) -> None:
    """Reject coincident vertices (relative to the polytope's size) with ``error``."""
    size = np.max(np.linalg.norm(v - v.mean(axis=0), axis=1))
    if size == 0.0:
        raise error(f"{path}: all {len(v)} vertices coincide")
    from scipy.spatial import cKDTree  # O(n log n): a polytope may have thousands of vertices
    dist, idx = cKDTree(v).query(v, k=2)
    a = int(np.argmin(dist[:, 1]))
    b = int(idx[a, 1]) if idx[a, 1] != a else int(idx[a, 0])
    gap = dist[a, 1]
    if gap <= 1e-12 * size:
        raise error(f"{path}: vertices {min(a, b)} and {max(a, b)} coincide "
                         f"(distance {gap:.3g}, polytope size {size:.3g})")
