"""What a scene may ask for: file size, YAML shape, magnitudes, and an estimate of its memory.

Every bound here is checked before the thing it bounds is allocated, so a bad scene is
refused in a fraction of a second with a one-line ``SceneError`` (exit code 2) that names
the key, the estimate and the limit.  docs/guide/scenes.md says why each value.
"""

import math
import re
from collections.abc import Iterable
from dataclasses import dataclass

from ..errors import ParameterError, SceneError

MAX_FILE_BYTES = 2 * 2**20        # a scene file; explicit vertices of ~25,000 triangles fit
MAX_DEPTH = 32                    # YAML nesting (a scene needs 7: groups[0].agents[0]...)
MAX_NODES = 1_000_000             # YAML values after alias expansion (billion laughs)
MAX_DIMENSION = 64                # d: rotations are d x d, a step costs O(N d^3)
MAX_VERTICES = 4096               # per polytope (hypercube k <= 12); metrics visit every vertex
MAX_SAMPLES = 100_000             # metric samples per run (each costs a pass over all vertices)
MAX_LENGTH = 1e12                 # |coordinate|, size, L, spreads: squares stay finite, resolved
MIN_SIZE = 1e-12                  # circumradius and scales: below this the shape is round-off
MAX_RATE = 1e15                   # kappa/gamma, kappa/m, gamma/m (1/s): stability analysis finite
MIN_T_END = 1e-12                 # time.t_end; samples closer than 1e-9 max(1, t_end) are merged
MIN_RELATIVE_TOLERANCE = 1e-14    # ~50 ulp: an adaptive tolerance below this is unattainable
DEFAULT_MEMORY = 2 * 2**30        # estimated bytes of a run; --memory-limit overrides
FLOAT = 8                         # bytes
WORKING_COPIES = 6                # a step holds the state, its stages and the mean field


@dataclass(frozen=True)
class Limits:
    """Bounds a scene is checked against; ``memory`` is the one users raise (--memory-limit)."""

    memory: int = DEFAULT_MEMORY


DEFAULT_LIMITS = Limits()


def format_bytes(n: float) -> str:
    """1.5 GiB, 300 MiB, 12 KiB."""
    if not n < 2**40 * 1e6:
        return f"{float(n):.3g} bytes" if n < 1e300 else "more than 1e300 bytes"
    for unit, size in (("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if n >= size:
            return f"{n / size:.3g} {unit}"
    return f"{int(n)} bytes"


def count_text(n: float) -> str:
    """An integer as people read it: 1000000, 1.2e+15, more than 1e300."""
    return str(n) if n < 10**12 else f"{float(n):.3g}" if n < 10**300 else "more than 1e300"


_SIZE = re.compile(r"^\s*([0-9]*\.?[0-9]+(?:[eE][-+]?[0-9]+)?)\s*([kKmMgGtT]?)(?:i?[bB])?\s*$")


def parse_size(text: object) -> int:
    """'512M', '8G', '1.5GiB', '1000000' -> bytes (binary units); ParameterError otherwise."""
    match = _SIZE.match(str(text))
    if not match:
        raise ParameterError(f"expected a size such as 512M or 8G, got {text!r}")
    value = float(match.group(1)) * 1024 ** " KMGT".index(match.group(2).upper() or " ")
    if not (math.isfinite(value) and value >= 2**20):
        raise ParameterError(f"a memory limit must be at least 1M, got {text!r}")
    return int(value)


class Budget:
    """A running estimate of a scene's memory, charged before each allocation."""

    def __init__(self, limits: Limits | None = None) -> None:
        self.limits = limits or DEFAULT_LIMITS
        self.total = 0.0
        self.items: list[tuple[str, float, str]] = []

    def charge(self, path: str, nbytes: float, what: str) -> None:
        """Add ``nbytes`` (``what``, at key ``path``); refuse once the total exceeds the limit."""
        self.total += float(nbytes)
        self.items.append((path, nbytes, what))
        if not self.total <= self.limits.memory:
            raise SceneError(f"{path}: the scene needs about {format_bytes(self.total)} "
                             f"({what}), more than the memory limit "
                             f"{format_bytes(self.limits.memory)}; raise it with --memory-limit "
                             f"if the machine has the memory")

    def charge_agents(self, path: str, count: int, vertices: int, dim: int,
                      order: int) -> None:
        """Centroids, rotations (and velocities) with working copies, plus one vertex pass."""
        per_agent = (dim + dim * dim) * (2 if order == 2 else 1) * WORKING_COPIES
        per_agent += 3 * vertices * dim                       # vertex positions in the metrics
        self.charge(path, float(count) * per_agent * FLOAT,
                    f"{count_text(count)} agents x {vertices} vertices in R^{dim}")


def shape_vertex_count(family: str, k: float) -> tuple[int, int]:
    """Vertices and edges of a shape family's member, without building it."""
    k = int(k)
    if family == "polygon":
        return k, k
    if family == "simplex":
        return k + 1, (k + 1) * k // 2
    if family == "hypercube":
        return 2 ** min(k, 4096), k * 2 ** max(min(k, 4096) - 1, 0)
    return 2 * k, 2 * k * (k - 1)                             # cross_polytope


def check_rates(model_path: str, rates: Iterable[tuple[str, float]]) -> None:
    """Refuse rates (1/s) beyond MAX_RATE: the linearisation and its step limits overflow."""
    for name, value in rates:
        if not value <= MAX_RATE:
            raise SceneError(f"{model_path}: the rate {name} = {value:.3g} exceeds "
                             f"{MAX_RATE:g}/s; no time step of a double-precision run can "
                             f"resolve it")
