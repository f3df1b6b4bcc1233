"""The ensembles of a sweep: one scene file as template, a grid of cells, B seeds per cell.

A *cell* fixes what one batch shares (d, N, model order, kappa, gamma, m); its ensembles
are the template scene built with seeds seed, seed + 1, ... (the scene's own random draws),
optionally with the rotations redrawn at a prescribed initial rotation diameter
D0 = max_{i,j} |O_i - O_j|_F (Prop 2.2, Thm 4.2) drawn uniformly in a range.
"""

import copy
import itertools
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from ..errors import ParameterError
from ..limits import DEFAULT_MEMORY
from ..model import GroupState, State
from ..scene import Scene, build_scene, resolve_scene_path
from ..yamlfile import parse_yaml, read_scene_file

#: bytes a batch holds per state entry: stage copies, slopes, metrics and the D0 draw
BYTES_PER_ENTRY = 8 * 64
#: bisection steps on the spread of the rotations (D0 to ~1e-15 relative)
BISECTION_STEPS = 60


@dataclass(frozen=True)
class Cell:
    """What one batch shares; None keeps the template scene's value."""

    dim: int | None = None
    agents: int | None = None
    order: int | None = None
    kappa: float | None = None
    gamma: float | None = None
    mass: float | None = None

    def label(self, scene: Scene) -> dict:
        m = scene.model
        return {"d": m.dim, "N": m.n_agents, "order": m.order, "kappa": m.kappa,
                "gamma": m.gamma, "mass": m.mass}


def grid(dims: Iterable[int | None] = (None,), agents: Iterable[int | None] = (None,),
         orders: Iterable[int | None] = (None,), kappas: Iterable[float | None] = (None,),
         gammas: Iterable[float | None] = (None,),
         masses: Iterable[float | None] = (None,)) -> list[Cell]:
    """Every combination of the given values (first-order cells ignore the masses)."""
    cells: list[Cell] = []
    for d, n, o, k, g, m in itertools.product(dims, agents, orders, kappas, gammas, masses):
        cell = Cell(d, n, o, k, g, None if o == 1 else m)
        if cell not in cells:
            cells.append(cell)
    return cells


def template(source: str) -> dict:
    """The scene file's data (a path or a shipped scene name)."""
    path = resolve_scene_path(source)
    return parse_yaml(read_scene_file(path), path)


def cell_data(data: dict, cell: Cell) -> dict:
    """The template with the cell's values set."""
    out = copy.deepcopy(data)
    model = dict(out.get("model") or {})
    if cell.dim is not None:
        out["dimension"] = cell.dim
    groups = out.get("groups")
    if not isinstance(groups, list) or len(groups) != 1 or not isinstance(groups[0], dict):
        raise ParameterError("a sweep takes a scene with exactly one group")
    group = dict(groups[0])
    if cell.agents is not None:
        group["count"] = cell.agents
    if cell.order is not None:
        model["order"] = cell.order
    for key in ("kappa", "gamma", "mass"):
        if getattr(cell, key) is not None:
            model[key] = getattr(cell, key)
    if model.get("order", 1) == 1:
        model.pop("mass", None)
        group.pop("velocities", None)
    out["model"], out["groups"] = model, [group]
    return out


def cell_scenes(data: dict, cell: Cell, ensembles: int, seed: int,
                d0: tuple[float, float] | None = None,
                memory: int = DEFAULT_MEMORY) -> list[Scene]:
    """The cell's ensembles: seeds seed .. seed + B - 1; rotations at D0 in ``d0`` = (lo, hi).

    Refuses (ParameterError) a batch whose arrays would need more than ``memory`` bytes.
    """
    base = cell_data(data, cell)
    first = build_scene(dict(base, seed=seed))
    n, d = first.model.n_agents, first.model.dim
    need = BYTES_PER_ENTRY * ensembles * n * (d * d + 2 * d)
    if need > memory:
        raise ParameterError(f"{ensembles} ensembles of {n} agents in d = {d} need about "
                             f"{need / 2**30:.3g} GiB, more than the {memory / 2**30:.3g} GiB "
                             "limit; run fewer ensembles per cell")
    scenes = [first] + [build_scene(dict(base, seed=seed + b)) for b in range(1, ensembles)]
    if d0 is None:
        return scenes
    lo, hi = d0
    targets = np.array([lo + (hi - lo) * np.random.default_rng((seed + b, 1)).random()
                        for b in range(ensembles)])
    mats = rotations_at_diameter(scenes[0].model.dim, scenes[0].model.n_agents, targets,
                                 [seed + b for b in range(ensembles)])
    return [with_rotations(s, m) for s, m in zip(scenes, mats)]


def with_rotations(scene: Scene, mats: np.ndarray) -> Scene:
    """The scene with its group's rotations replaced by matrices (N, d, d)."""
    grp = scene.model.rotations
    gs = scene.initial.all_groups()[0]
    new = GroupState(gs.x, grp.from_matrices(mats), gs.v, gs.w)
    return replace(scene, initial=State(0.0, (new,)))


def _diameters(mats: np.ndarray) -> np.ndarray:
    """max_{i,j} |O_i - O_j|_F per ensemble of (B, N, d, d)."""
    flat = mats.reshape(mats.shape[0], mats.shape[1], -1)
    diff = flat[:, :, None] - flat[:, None]
    return np.sqrt(np.einsum("bijk,bijk->bij", diff, diff).max(axis=(1, 2)))


def rotations_at_diameter(dim: int, n: int, targets: np.ndarray,
                          seeds: Sequence[int]) -> np.ndarray:
    """(B, N, d, d) rotations O_i = exp(s theta_i A_i) P with max |O_i - O_j|_F = target.

    Per ensemble (its own seed): P Haar-random, A_i random skew of unit spectral norm,
    theta_i uniform, rescaled to span [0, 1] (so D0 reaches 2 sqrt(2) at s = pi); the
    spread s in [0, pi] is found by bisection on the rotation diameter (continuous in s,
    0 at s = 0).
    """
    if np.any(targets < 0):
        raise ParameterError("--d0: rotation diameters are >= 0")
    b = len(targets)
    gens = np.empty((b, n, dim, dim))
    bases = np.empty((b, dim, dim))
    for k, seed in enumerate(seeds):
        rng = np.random.default_rng((seed, 2))
        g = rng.standard_normal((n, dim, dim))
        a = g - np.swapaxes(g, 1, 2)
        a /= np.linalg.norm(a, 2, axis=(1, 2))[:, None, None]
        theta = rng.random(n)
        theta = (theta - theta.min()) / max(np.ptp(theta), 1e-300)
        gens[k] = a * theta[:, None, None]
        q, r = np.linalg.qr(rng.standard_normal((dim, dim)))
        q = q * np.sign(np.diag(r))
        if np.linalg.det(q) < 0:
            q[:, 0] = -q[:, 0]
        bases[k] = q

    lam, vecs = np.linalg.eigh(1j * gens)          # A = U diag(-i lam) U^H (i A Hermitian)

    def at(s: np.ndarray) -> np.ndarray:
        phase = np.exp(-1j * s[:, None, None] * lam)
        exp_a = np.einsum("bnij,bnj,bnkj->bnik", vecs, phase, vecs.conj()).real
        return exp_a @ bases[:, None]

    reach = _diameters(at(np.full(b, np.pi)))
    if np.any(reach < targets):
        worst = float(targets[np.argmax(targets - reach)])
        raise ParameterError(f"--d0: a rotation diameter of {worst:g} is not reachable by the "
                             f"draw (at most {float(reach.min()):.3g} here); lower the range")
    lo, hi = np.zeros(b), np.full(b, np.pi)
    for _ in range(BISECTION_STEPS):
        mid = 0.5 * (lo + hi)
        below = _diameters(at(mid)) < targets
        lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
    return at(0.5 * (lo + hi))
