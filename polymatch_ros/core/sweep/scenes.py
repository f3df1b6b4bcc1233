"""The ensembles of a sweep: one scene file as template, a grid of cells, B seeds per cell.

A *cell* fixes what one batch shares (d, N, model order, kappa, gamma, m, graph); its
ensembles are the template scene built with seeds seed, seed + 1, ... (the scene's own
random draws), optionally with the rotations redrawn at a prescribed initial rotation
diameter D0 = max_{i,j} |O_i - O_j|_F (Prop 2.2, Thm 4.2) drawn uniformly in a range.

A cell's graph is the template's ``graph`` key or a short spec (``graph_spec``):
``complete``, ``ring:K``, ``k_nearest:K``, ``random:P``; the template's graph options
(``normalise``) carry over.  A random graph without a seed of its own is drawn anew for
every ensemble, seeded by the ensemble's seed, and drawn again (at most GRAPH_DRAWS times)
while it is disconnected unless the graph says ``allow_disconnected: true``: the
ensembles of such a cell sample connected Erdos-Renyi graphs G(N, p).
"""

import copy
import itertools
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from ..errors import ParameterError, SceneError
from ..model import GroupState, State
from ..scenes.limits import DEFAULT_MEMORY
from ..scenes.scene import Scene, build_scene, resolve_scene_path
from ..scenes.yamlfile import parse_yaml, read_scene_file

#: bytes a batch holds per state entry: stage copies, slopes, metrics and the D0 draw
BYTES_PER_ENTRY = 8 * 64
#: bisection steps on the spread of the rotations (D0 to ~1e-15 relative)
BISECTION_STEPS = 60
#: draws of a random graph per ensemble until one is connected
GRAPH_DRAWS = 1000
#: the graph kinds a short spec names, with the type of their parameter
GRAPH_SPECS = {"ring": int, "k_nearest": int, "random": float}


@dataclass(frozen=True)
class Cell:
    """What one batch shares; None keeps the template scene's value."""

    dim: int | None = None
    agents: int | None = None
    order: int | None = None
    kappa: float | None = None
    gamma: float | None = None
    mass: float | None = None
    graph: str | None = None       # a ``graph_spec`` text
    normalise: str | None = None   # the graph's weights: "size" (kappa/N) or "degree"

    def label(self, scene: Scene, graph: str = "complete") -> dict:
        m = scene.model
        return {"d": m.dim, "N": m.n_agents, "order": m.order, "kappa": m.kappa,
                "gamma": m.gamma, "mass": m.mass, "graph": graph}


def graph_text(data: dict) -> str:
    """A scene file's graph (top level, as ``cell_data`` leaves it) in ``graph_spec`` form."""
    spec = data.get("graph")
    if spec is None or spec == "complete":
        return "complete"
    if not isinstance(spec, dict):
        return str(spec)
    for kind in GRAPH_SPECS:
        if kind in spec:
            value = spec[kind]
            if kind == "random" and isinstance(value, dict):
                value = value.get("p")
            return f"{kind}:{value}"
    return "edges"


def graph_spec(text: str) -> str | dict:
    """``complete`` | ``ring:K`` | ``k_nearest:K`` | ``random:P`` as a scene's ``graph`` value."""
    if text == "complete":
        return text
    kind, _, value = text.partition(":")
    if kind not in GRAPH_SPECS or not value:
        raise ParameterError(f"--graph: expected complete, ring:K, k_nearest:K or random:P, "
                             f"got {text!r}")
    try:
        number = GRAPH_SPECS[kind](value)
    except ValueError:
        raise ParameterError(f"--graph: {kind} takes "
                             f"{'an integer' if kind != 'random' else 'a probability'}, "
                             f"got {value!r}") from None
    return {kind: {"p": number} if kind == "random" else number}


def grid(dims: Iterable[int | None] = (None,), agents: Iterable[int | None] = (None,),
         orders: Iterable[int | None] = (None,), kappas: Iterable[float | None] = (None,),
         gammas: Iterable[float | None] = (None,),
         masses: Iterable[float | None] = (None,),
         graphs: Iterable[str | None] = (None,), normalise: str | None = None) -> list[Cell]:
    """Every combination of the given values (first-order cells ignore the masses)."""
    cells: list[Cell] = []
    for d, n, o, k, g, m, gr in itertools.product(dims, agents, orders, kappas, gammas, masses,
                                                 graphs):
        cell = Cell(d, n, o, k, g, None if o == 1 else m, gr, normalise)
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
    graph = out.get("graph", groups[0].get("graph"))
    if isinstance(graph, dict) and "radius" in graph:
        raise ParameterError("a sweep takes fixed graphs (complete, ring, k_nearest, random, "
                             "edges), not a proximity graph ({radius: R}): its edges change "
                             "with the state; run it with `polymatch simulate`")
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
    own = group.pop("graph", None)            # one group: its graph is the scene's
    if own is not None:
        out["graph"] = own
    if cell.graph is not None:
        out["graph"] = _with_options(graph_spec(cell.graph), out.get("graph"))
    if cell.normalise is not None and isinstance(out.get("graph"), dict):
        out["graph"] = dict(out["graph"], normalise=cell.normalise)   # complete: no weights
    out["model"], out["groups"] = model, [group]
    return out


def _with_options(spec: str | dict, template: object) -> str | dict:
    """A cell's graph with the template graph's ``normalise`` and ``allow_disconnected``."""
    if not isinstance(spec, dict) or not isinstance(template, dict):
        return spec
    return dict(spec, **{k: template[k] for k in ("normalise", "allow_disconnected")
                         if k in template})


def ensemble_data(base: dict, seed: int) -> dict:
    """One ensemble's scene data: its seed, and its own random graph (module doc)."""
    spec = base.get("graph")
    out = dict(base, seed=seed)
    if not (isinstance(spec, dict) and isinstance(spec.get("random"), dict)
            and "seed" not in spec["random"]):
        return out
    size = base["groups"][0].get("count")
    if not isinstance(size, int) or isinstance(size, bool) or size < 1:
        return out                            # build_scene says what is wrong with it
    from ..graph import build_graph, check_connected
    for draw in range(GRAPH_DRAWS):
        own = dict(spec, random=dict(spec["random"], seed=seed * GRAPH_DRAWS + draw))
        graph = build_graph(own, "graph", size)          # a bad p is refused here, once
        if spec.get("allow_disconnected"):
            break
        try:
            check_connected(graph, "graph")
            break
        except SceneError:
            continue
    else:
        raise ParameterError(f"graph: random p = {spec['random'].get('p')} gave no connected "
                             f"graph of {size} agents in {GRAPH_DRAWS} draws")
    return dict(out, graph=own)


def cell_scenes(data: dict, cell: Cell, ensembles: int, seed: int,
                d0: tuple[float, float] | None = None,
                memory: int = DEFAULT_MEMORY) -> list[Scene]:
    """The cell's ensembles: seeds seed .. seed + B - 1; rotations at D0 in ``d0`` = (lo, hi).

    Refuses (ParameterError) a batch whose arrays would need more than ``memory`` bytes.
    """
    base = cell_data(data, cell)
    first = _ensemble(base, seed)
    n, d = first.model.n_agents, first.model.dim
    need = BYTES_PER_ENTRY * ensembles * n * (d * d + 2 * d)
    if need > memory:
        raise ParameterError(f"{ensembles} ensembles of {n} agents in d = {d} need about "
                             f"{need / 2**30:.3g} GiB, more than the {memory / 2**30:.3g} GiB "
                             "limit; run fewer ensembles per cell")
    scenes = [first] + [_ensemble(base, seed + b) for b in range(1, ensembles)]
    if d0 is None:
        return scenes
    lo, hi = d0
    targets = np.array([lo + (hi - lo) * np.random.default_rng((seed + b, 1)).random()
                        for b in range(ensembles)])
    mats = rotations_at_diameter(scenes[0].model.dim, scenes[0].model.n_agents, targets,
                                 [seed + b for b in range(ensembles)])
    return [with_rotations(s, m) for s, m in zip(scenes, mats)]


def _ensemble(base: dict, seed: int) -> Scene:
    """The ensemble of one seed; a graph it cannot match on is refused with the seed named."""
    try:
        return build_scene(ensemble_data(base, seed))
    except SceneError as exc:
        if "disconnected" not in str(exc):
            raise
        raise SceneError(f"seed {seed}: {exc} (every ensemble's graph must be connected, or "
                         "the scene's graph must say allow_disconnected: true)") from None


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
