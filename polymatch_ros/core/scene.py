"""Scene files: YAML -> validated ``Scene`` (model, initial state, integrator, times).

Every validation error is a ``SceneError`` whose message starts with the
offending key path (``groups[1].rotations.within: ...``); the CLI prints it
as one line and exits with code 2.  The format is documented in README.md.

Centroids are stored as offsets from ``Scene.origin`` (the mean of the
initial centroids).  The dynamics is translation invariant, so this changes
nothing in the model but keeps the shape resolved to round-off relative to
its own size even when coordinates are of magnitude 1e9.
"""

import math
import os
import sys
import warnings
from dataclasses import dataclass, field, replace

import numpy as np
import yaml

from . import graph, initial
from .checks import Map, vector
from .decompose import RotationNotUniqueWarning, decompose
from .errors import SceneError
from .model import Group, GroupState, Model, State, validate_model
from .shapes import make_shape
from .so import group_for


@dataclass(frozen=True)
class IntegratorSpec:
    method: str = "auto"
    dt: float = None
    tolerance: float = None
    max_steps: int = 10_000_000


@dataclass
class Scene:
    name: str
    description: str
    model: Model
    initial: State
    origin: np.ndarray
    integrator: IntegratorSpec
    t_end: float
    samples: np.ndarray
    snapshots: tuple
    tolerance: float
    expect_convergence: bool
    seed: int
    path: str = None
    notes: list = field(default_factory=list)

    @property
    def dim(self):
        return self.model.dim


def shipped_config_dirs():
    """Where shipped scenes live: the repository's config/, then the installed share/ directory."""
    dirs = []
    here = os.path.dirname(os.path.abspath(__file__))
    dirs.append(os.path.join(os.path.dirname(os.path.dirname(here)), "config"))
    try:
        from ament_index_python.packages import get_package_share_directory
        dirs.append(os.path.join(get_package_share_directory("polymatch_ros"), "config"))
    except Exception:   # no ament index (plain pip install): the repository copy is all there is
        pass
    dirs.append(os.path.join(sys.prefix, "share", "polymatch_ros", "config"))
    return [d for d in dirs if os.path.isdir(d)]


def resolve_scene_path(name):
    """A path as given, or a shipped scene by name (``congruent_triangles``)."""
    if os.path.isfile(name):
        return name
    stem = name[:-5] if name.endswith(".yaml") else name
    for d in shipped_config_dirs():
        cand = os.path.join(d, stem + ".yaml")          # e.g. congruent_triangles, extremes/stiff_mass
        if os.path.isfile(cand):
            return cand
    raise SceneError(f"{name}: no such scene file (nor a shipped scene of that name; "
                         f"see `polymatch scenes`)")


def load_scene(source, overrides=None):
    """Load and validate a scene from a file path, a shipped scene name, a YAML string or a dict."""
    path = None
    if isinstance(source, dict):
        data = source
    else:
        text = source
        if isinstance(source, os.PathLike) or (isinstance(source, str) and "\n" not in source):
            path = resolve_scene_path(os.fspath(source))
            with open(path, encoding="utf-8") as fh:
                text = fh.read()
        try:
            data = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            mark = getattr(exc, "problem_mark", None)
            where = f"line {mark.line + 1}" if mark else "?"
            raise SceneError(f"{path or 'scene'}: not valid YAML ({where}: "
                             f"{getattr(exc, 'problem', exc)})") from None
    if overrides:
        data = _apply_overrides(data, overrides)
    scene = build_scene(data)
    scene.path = path
    return scene


def _apply_overrides(data, overrides):
    """Set dotted keys (``integrator.dt``) to values; used by the CLI."""
    import copy
    data = copy.deepcopy(data)
    for key, value in overrides.items():
        if value is None:
            continue
        node = data
        parts = key.split(".")
        for p in parts[:-1]:
            node = node.setdefault(p, {})
        node[parts[-1]] = value
    return data


def build_scene(data):
    top = Map(data, "", ("name", "description", "dimension", "seed", "model", "integrator",
                          "time", "convergence", "groups", "figure", "graph"))
    dim = top.number("dimension", integer=True, minimum=2)
    seed = top.number("seed", 0, integer=True, minimum=0)
    rng = np.random.default_rng(seed)
    notes = []

    mm = Map(top.raw("model", {}), "model",
              ("order", "kappa", "gamma", "mass", "kappa_2", "L", "representation", "centroids"))
    order = mm.number("order", 1, integer=True)
    if order not in (1, 2):
        raise SceneError(f"model.order: must be 1 (A-2) or 2 (A-1), got {order}")
    kappa = mm.number("kappa", 1.0, minimum=0)
    gamma = mm.number("gamma", 1.0, minimum=0)
    mass = mm.number("mass", 0.0 if order == 1 else 1.0, minimum=0)
    if order == 1 and mass != 0:
        raise SceneError(f"model.mass: the first-order model (A-2) has m = 0, got {mass}; set order: 2")
    kappa_2 = mm.number("kappa_2", 0.0, minimum=0)
    L = mm.number("L", 0.0, minimum=0)
    representation = mm.raw("representation", "auto")
    try:
        rotations = group_for(dim, representation)
    except ValueError as exc:
        raise SceneError(f"model.representation: {exc}") from None

    raw_groups = top.raw("groups")
    if not isinstance(raw_groups, list) or not raw_groups:
        raise SceneError("groups: required, a non-empty list of groups")
    groups, states = [], []
    start = 0
    names = set()
    for gi, raw in enumerate(raw_groups):
        g, gs = _build_group(raw, f"groups[{gi}]", dim, order, rng, rotations, start, notes)
        if g.name in names:
            raise SceneError(f"groups[{gi}].name: duplicate group name {g.name!r}")
        names.add(g.name)
        groups.append(g)
        states.append(gs)
        start += g.size
    # communication graphs: core.graph parses and validates the scene's and each group's `graph`
    graphs = graph.group_graphs(top.raw("graph"), raw_groups, [g.size for g in groups],
                                [gs.x for gs in states])
    groups = [replace(g, graph=gr) for g, gr in zip(groups, graphs)]
    if (kappa_2 > 0 or mm.has("L")) and len(groups) == 1:
        notes.append("one group: the inter-group potential (kappa_2, L) has nothing to act on and is not modelled")
        kappa_2 = 0.0

    centroids = mm.raw("centroids", "exact")
    if centroids not in ("exact", "integrated"):
        raise SceneError(f"model.centroids: expected exact or integrated, got {centroids!r}")
    model = Model(dim=dim, order=order, kappa=kappa, gamma=gamma, mass=mass, groups=tuple(groups),
                  rotations=rotations, kappa_2=kappa_2, L=L, centroids=centroids)
    validate_model(model)

    all_x = np.concatenate([gs.x for gs in states])
    origin = all_x.mean(axis=0)
    for gs in states:
        gs.x = gs.x - origin
    initial = State(0.0, tuple(states))

    tm = Map(top.raw("time", {}), "time", ("t_end", "samples"))
    t_end = tm.number("t_end", 20.0, positive=True)
    samples = _samples(tm.raw("samples"), "time.samples", t_end)
    im = Map(top.raw("integrator", {}), "integrator", ("method", "dt", "tolerance", "max_steps"))
    method = im.raw("method", "auto")
    if not isinstance(method, str):
        raise SceneError(f"integrator.method: expected a name, got {method!r}")
    dt = im.number("dt", 0.0, positive=False) if im.has("dt") else None
    if dt is not None and not dt > 0:
        raise SceneError(f"integrator.dt: must be > 0, got {dt}")
    tol = im.number("tolerance", 0.0) if im.has("tolerance") else None
    if tol is not None and not 0 < tol < 1:
        raise SceneError(f"integrator.tolerance: must be in (0, 1), got {tol}")
    max_steps = im.number("max_steps", 10_000_000, integer=True, minimum=1)
    cm = Map(top.raw("convergence", {}), "convergence", ("tolerance", "expected"))
    conv_tol = cm.number("tolerance", 1e-6, positive=True)
    expected = cm.raw("expected", True)
    if not isinstance(expected, bool):
        raise SceneError(f"convergence.expected: expected true or false, got {expected!r}")
    fm = Map(top.raw("figure", {}), "figure", ("snapshots",))
    snaps = fm.raw("snapshots", [0, 3, 6, 12])
    snapshots = tuple(float(t) for t in vector(snaps, "figure.snapshots") if t <= t_end)
    name = top.raw("name", "scene")
    return Scene(name=str(name), description=str(top.raw("description", "")), model=model,
                 initial=initial, origin=origin,
                 integrator=IntegratorSpec(method, dt, tol, max_steps), t_end=t_end,
                 samples=samples, snapshots=snapshots, tolerance=conv_tol,
                 expect_convergence=expected, seed=seed, notes=notes)


def _samples(raw, path, t_end):
    if raw is None:
        return np.linspace(0.0, t_end, 101)
    if isinstance(raw, dict):
        sm = Map(raw, path, ("every", "count"))
        if sm.has("every") == sm.has("count"):
            raise SceneError(f"{path}: give exactly one of 'every' or 'count'")
        if sm.has("every"):
            every = sm.number("every", positive=True)
            n = int(math.floor(t_end / every + 1e-9))
            times = every * np.arange(n + 1)
            return np.unique(np.append(times[times <= t_end], t_end))
        count = sm.number("count", integer=True, minimum=2)
        return np.linspace(0.0, t_end, count)
    times = vector(raw, path)
    if np.any(times < 0) or np.any(times > t_end):
        raise SceneError(f"{path}: sample times must lie in [0, t_end = {t_end}]")
    return np.unique(np.concatenate([[0.0], times, [t_end]]))


def _build_group(raw, path, dim, order, rng, rotations, start, notes):
    gm = Map(raw, path, ("name", "shape", "size", "count", "centroids", "rotations", "scales",
                          "velocities", "agents", "similar", "graph"))
    name = str(gm.raw("name", f"group{start}"))
    explicit = gm.has("agents")
    if explicit:
        for key in ("count", "centroids", "rotations", "scales"):
            if gm.has(key):
                raise SceneError(f"{gm.at(key)}: not allowed together with 'agents' (explicit vertices)")
    similar = gm.raw("similar", gm.has("scales"))
    if not isinstance(similar, bool):
        raise SceneError(f"{gm.at('similar')}: expected true or false")
    size = gm.number("size", 1.0, positive=True)

    if gm.has("shape"):
        shape = make_shape(gm.raw("shape"), gm.at("shape"))
        if shape.dim > dim:
            raise SceneError(f"{gm.at('shape')}: shape {shape.name!r} lives in R^{shape.dim}, "
                             f"the scene has dimension {dim}")
        shape = shape.embedded(dim).scaled(size)
    elif not explicit:
        raise SceneError(f"{gm.at('shape')}: required (or give explicit 'agents' with vertices)")
    else:
        shape = None

    if explicit:
        agents = gm.raw("agents")
        if not isinstance(agents, list) or not agents:
            raise SceneError(f"{gm.at('agents')}: expected a non-empty list of {{vertices: ...}}")
        verts, vels, omegas = [], [], []
        for ai, a in enumerate(agents):
            am = Map(a, f"{gm.at('agents')}[{ai}]", ("vertices", "velocity", "angular_velocity"))
            if not am.has("vertices"):
                raise SceneError(f"{am.at('vertices')}: required")
            verts.append(am.raw("vertices"))
            vels.append(am.raw("velocity"))
            omegas.append(am.raw("angular_velocity"))
        if shape is None:
            first = np.array(verts[0], dtype=float)
            shape = make_shape({"vertices": first.tolist()}, f"{gm.at('agents')}[0].vertices")
        ref = shape.vertices
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", RotationNotUniqueWarning)
            cents, mats, scales = decompose(verts, ref, similar=similar,
                                            label=f"{gm.at('agents')}: polytope")
        notes.extend(str(w.message) for w in caught)
        if similar:
            s0 = scales.mean()
            ref, scales = ref * s0, scales / s0
            shape = type(shape)(shape.name, ref, shape.edges)
        count = len(verts)
        rot = rotations.from_matrices(mats)
        v = initial.explicit_vectors(vels, f"{gm.at('agents')}", "velocity", dim, order)
        w = initial.explicit_omegas(omegas, f"{gm.at('agents')}", dim, order, rotations)
        group = Group(name, count, shape.vertices, shape.edges,
                      scales if similar else None, start)
        if order == 1 and (v is not None or w is not None):
            raise SceneError(f"{gm.at('agents')}: velocities are only meaningful for model.order = 2")
        v = np.zeros((count, dim)) if (order == 2 and v is None) else v
        w = rotations.algebra_zeros(count) if (order == 2 and w is None) else w
        return group, GroupState(cents, rot, v if order == 2 else None, w if order == 2 else None)

    count = gm.number("count", integer=True, minimum=1)
    if shape.rank < dim:
        notes.append(f"{path}: shape {shape.name!r} spans {shape.rank} of {dim} dimensions "
                     f"(Lemma 3.2 assumes {dim}); "
                     + ("its rotation is still unique (det +1 fixes the normal)"
                        if shape.rank == dim - 1 else
                        "rotations that differ only in the complement leave its vertices in place"))
    cents = initial.centroids(gm.raw("centroids", {"box": [-5.0, 5.0]}), gm.at("centroids"), dim, count, rng)
    mats = initial.rotations(gm.raw("rotations", "uniform"), gm.at("rotations"), dim, count, rng)
    scales = None
    if similar:
        if not gm.has("scales"):
            raise SceneError(f"{gm.at('scales')}: required when similar is true")
        scales = initial.scales(gm.raw("scales"), gm.at("scales"), count, rng)
    vel = gm.raw("velocities")
    if order == 1 and vel is not None:
        raise SceneError(f"{gm.at('velocities')}: only meaningful for model.order = 2")
    v = w = None
    if order == 2:
        v, wm = initial.velocities(vel or {}, gm.at("velocities"), dim, count, rng)
        w = rotations.algebra_from_skew(wm)
    group = Group(name, count, shape.vertices, shape.edges, scales, start)
    return group, GroupState(cents, rotations.from_matrices(mats), v, w)


