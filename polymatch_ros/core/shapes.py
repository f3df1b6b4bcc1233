"""A small library of polytopes, each a centred reference vertex set r_a with edges.

The paper identifies a polytope with its vertex set {x_a} and writes every
member of a congruent ensemble as x^i_a = xbar^i + O^i r_a with sum_a r_a = 0
(Section 3).  ``Shape.vertices`` is that r_a, scaled so the circumradius is
``size``.
"""

from dataclasses import dataclass
from itertools import combinations, product

import numpy as np

from .errors import SceneError


@dataclass(frozen=True)
class Shape:
    """A centred reference polytope: vertices (n, k) and edges [(a, b), ...]."""

    name: str
    vertices: np.ndarray
    edges: tuple

    @property
    def dim(self):
        return self.vertices.shape[1]

    @property
    def circumradius(self):
        return float(np.max(np.linalg.norm(self.vertices, axis=1)))

    @property
    def rank(self):
        """Dimension of span{r_a}; the paper's Lemma 3.2 assumes it equals d."""
        return int(np.linalg.matrix_rank(self.vertices, tol=1e-9 * max(self.circumradius, 1e-300)))

    def embedded(self, dim):
        """The same shape in R^dim (zero-padded); a triangle becomes a triangle in R^3."""
        if dim < self.dim:
            raise SceneError(f"shape {self.name!r} lives in R^{self.dim}, the scene in R^{dim}")
        pad = np.zeros((self.vertices.shape[0], dim - self.dim))
        return Shape(self.name, np.hstack([self.vertices, pad]), self.edges)

    def scaled(self, size):
        r = self.circumradius
        return Shape(self.name, self.vertices * (size / r), self.edges)


def _centred(vertices):
    v = np.asarray(vertices, dtype=float)
    return v - v.mean(axis=0)


def polygon(n):
    """Regular n-gon in R^2, circumradius 1, first vertex on the +y axis."""
    if n < 3:
        raise SceneError(f"shape.polygon: a polygon needs at least 3 sides, got {n}")
    ang = np.pi / 2 + 2 * np.pi * np.arange(n) / n
    v = np.stack([np.cos(ang), np.sin(ang)], axis=1)
    return Shape(f"polygon{n}", _centred(v), tuple((a, (a + 1) % n) for a in range(n)))


def simplex(k):
    """Regular k-simplex in R^k (k + 1 vertices), circumradius 1."""
    if k < 1:
        raise SceneError(f"shape.simplex: dimension must be >= 1, got {k}")
    e = np.eye(k + 1) - 1.0 / (k + 1)        # centred standard basis of R^{k+1}
    _, _, vt = np.linalg.svd(e)
    v = e @ vt[:k].T                         # coordinates in the hyperplane sum = 0
    v /= np.max(np.linalg.norm(v, axis=1))
    return Shape(f"simplex{k}", _centred(v), tuple(combinations(range(k + 1), 2)))


def hypercube(k):
    """Cube [-1, 1]^k scaled to circumradius 1 (square for k = 2)."""
    v = np.array(list(product((-1.0, 1.0), repeat=k)))
    edges = tuple((a, b) for a, b in combinations(range(len(v)), 2)
                  if np.sum(v[a] != v[b]) == 1)
    return Shape(f"hypercube{k}", v / np.sqrt(k), edges)


def cross_polytope(k):
    """The 2k points +-e_i in R^k (octahedron for k = 3)."""
    v = np.vstack([np.eye(k), -np.eye(k)])
    edges = tuple((a, b) for a, b in combinations(range(2 * k), 2) if abs(a - b) != k)
    return Shape(f"cross_polytope{k}", v, edges)


_NAMED = {
    "triangle": lambda: polygon(3),
    "square": lambda: hypercube(2),
    "pentagon": lambda: polygon(5),
    "hexagon": lambda: polygon(6),
    "tetrahedron": lambda: simplex(3),
    "cube": lambda: hypercube(3),
    "octahedron": lambda: cross_polytope(3),
}

_FAMILIES = {"polygon": polygon, "simplex": simplex,
             "hypercube": hypercube, "cross_polytope": cross_polytope}


def shape_names():
    return sorted(_NAMED) + [f"{{{k}: n}}" for k in sorted(_FAMILIES)] + ["{vertices: [...], edges: [...]}"]


def make_shape(spec, path="shape"):
    """Build a Shape from a scene entry.

    ``spec`` is a name ("triangle", "tetrahedron", ...), ``{polygon: 5}``,
    ``{simplex: 4}``, ``{hypercube: 3}``, ``{cross_polytope: 4}``, or
    ``{vertices: [[...], ...], edges: [[0, 1], ...]}`` (edges optional).
    """
    if isinstance(spec, str):
        if spec not in _NAMED:
            raise SceneError(f"{path}: unknown shape {spec!r}; known: {', '.join(shape_names())}")
        shape = _NAMED[spec]()
        return Shape(spec, shape.vertices, shape.edges)
    if not isinstance(spec, dict) or not spec:
        raise SceneError(f"{path}: expected a shape name or a mapping, got {spec!r}")
    if "vertices" in spec:
        extra = set(spec) - {"vertices", "edges", "name"}
        if extra:
            raise SceneError(f"{path}.{sorted(extra)[0]}: unknown key")
        v = check_vertex_array(spec["vertices"], f"{path}.vertices")
        n = v.shape[0]
        edges = spec.get("edges")
        if edges is None:
            edges = tuple((a, (a + 1) % n) for a in range(n)) if n > 2 else ((0, 1),)
        else:
            try:
                edges = tuple((int(a), int(b)) for a, b in edges)
            except (TypeError, ValueError):
                raise SceneError(f"{path}.edges: expected a list of [a, b] vertex index pairs") from None
            bad = [e for e in edges if not (0 <= e[0] < n and 0 <= e[1] < n)]
            if bad:
                raise SceneError(f"{path}.edges: edge {list(bad[0])} refers to a vertex outside 0..{n - 1}")
        shape = Shape(str(spec.get("name", "custom")), _centred(v), edges)
        check_distinct_vertices(shape.vertices, path)
        return shape
    if len(spec) != 1:
        raise SceneError(f"{path}: expected one of {sorted(_FAMILIES)} or 'vertices', got keys {sorted(spec)}")
    (family, n), = spec.items()
    if family not in _FAMILIES:
        raise SceneError(f"{path}: unknown shape family {family!r}; known: {', '.join(sorted(_FAMILIES))}, vertices")
    if isinstance(n, bool) or not isinstance(n, int):
        raise SceneError(f"{path}.{family}: expected an integer, got {n!r}")
    if family != "polygon" and n < 1:
        raise SceneError(f"{path}.{family}: dimension must be >= 1, got {n}")
    return _FAMILIES[family](n)


def check_vertex_array(value, path):
    """A finite (n, k) float array with n >= 2, or a SceneError naming ``path``."""
    try:
        v = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise SceneError(f"{path}: expected a list of coordinate lists of equal length") from None
    if v.ndim != 2 or v.shape[1] < 1:
        raise SceneError(f"{path}: expected a list of coordinate lists of equal length")
    if v.shape[0] < 2:
        raise SceneError(f"{path}: a polytope needs at least 2 vertices, got {v.shape[0]}")
    bad = np.argwhere(~np.isfinite(v))
    if bad.size:
        a, c = bad[0]
        raise SceneError(f"{path}[{a}][{c}]: coordinate is not finite ({v[a, c]})")
    return v


def check_distinct_vertices(v, path, error=SceneError):
    """Reject coincident vertices (relative to the polytope's size) with ``error``."""
    size = np.max(np.linalg.norm(v - v.mean(axis=0), axis=1))
    if size == 0.0:
        raise error(f"{path}: all {len(v)} vertices coincide")
    diff = np.linalg.norm(v[:, None, :] - v[None, :, :], axis=2)
    diff[np.diag_indices(len(v))] = np.inf
    a, b = np.unravel_index(np.argmin(diff), diff.shape)
    if diff[a, b] <= 1e-12 * size:
        raise error(f"{path}: vertices {min(a, b)} and {max(a, b)} coincide "
                         f"(distance {diff[a, b]:.3g}, polytope size {size:.3g})")
