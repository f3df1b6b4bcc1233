"""Scene files: YAML -> validated ``Scene`` (model, initial state, integrator, times).

Every validation error is a ``SceneError`` whose message starts with the
offending key path (``groups[1].rotations.within: ...``); the CLI prints it
as one line and exits with code 2.  The format is documented in docs/guide/scenes.md.

Centroids are stored as offsets from ``Scene.origin`` (the mean of the
initial centroids).  The dynamics is translation invariant, so this changes
nothing in the model but keeps the shape resolved to round-off relative to
its own size even when coordinates are of magnitude 1e9.
"""

import math
import os
import sys
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from .. import graph
from ..errors import SceneError
from ..model import Model, State, validate_model
from ..proximity import BYTES_PER_WEIGHT
from ..robots.formation import check_separation, parse_formation
from ..robots.safety import SafetySpec, parse_safety
from ..so import group_for
from ..stepping.integrators import METHODS
from .checks import Map, describe, did_you_mean, number, vector
from .limits import (
    FLOAT,
    MAX_DIMENSION,
    MAX_LENGTH,
    MAX_RATE,
    MAX_SAMPLES,
    MIN_RELATIVE_TOLERANCE,
    MIN_T_END,
    Budget,
    Limits,
    check_rates,
)
from .scene_groups import GroupContext, build_group
from .yamlfile import parse_yaml, read_scene_file

#: the fixed step of a scene that names none, and the adaptive tolerance of one that names none
DEFAULT_DT = 0.05
DEFAULT_TOLERANCE = 1e-8


@dataclass(frozen=True)
class IntegratorSpec:
    method: str = "auto"
    dt: float | None = None
    tolerance: float | None = None
    max_steps: int = 10_000_000

    @property
    def step(self) -> float:
        """The fixed step the scene asks for, else ``DEFAULT_DT``."""
        return self.dt or DEFAULT_DT


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
    path: str | None = None
    notes: list[str] = field(default_factory=list)
    #: (N, d) formation offsets c_i (``core.robots.formation``): the states carry x_i - c_i; None:
    #: none
    formation: np.ndarray | None = None
    #: the robots' minimum separation (``core.robots.safety``); None: no safety filter
    safety: SafetySpec | None = None

    @property
    def dim(self) -> int:
        return self.model.dim


def shipped_config_dirs() -> list[str]:
    """Where shipped scenes live: the repository's config/, then share/polymatch_ros/config of
    the prefix the package is installed in (PREFIX/lib/pythonX.Y/site-packages/polymatch_ros:
    a colcon install's package prefix or a pip install's environment), then ``sys.prefix``'s."""
    package = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    install_prefix = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(package))))
    dirs = [os.path.join(os.path.dirname(package), "config"),
            os.path.join(install_prefix, "share", "polymatch_ros", "config"),
            os.path.join(sys.prefix, "share", "polymatch_ros", "config")]
    return list(dict.fromkeys(d for d in dirs if os.path.isdir(d)))


def resolve_scene_path(name: str) -> str:
    """A path as given, or a shipped scene by name (``congruent_triangles``)."""
    if os.path.isdir(name):
        raise SceneError(f"{name}: is a directory, not a scene file")
    if os.path.isfile(name):
        return name
    stem = name[:-5] if name.endswith(".yaml") else name
    for d in shipped_config_dirs():
        cand = os.path.join(d, stem + ".yaml")     # congruent_triangles, extremes/stiff_mass
        if os.path.isfile(cand):
            return cand
    raise SceneError(f"{name}: no such scene file (nor a shipped scene of that name; "
                     f"see `polymatch scenes`)")


def load_scene(source: str | os.PathLike[str] | dict[str, Any],
               overrides: dict[str, Any] | None = None, *,
               limits: Limits | None = None) -> Scene:
    """Load and validate a scene from a file path, a shipped scene name, a YAML string or a dict.

    ``limits`` (``core.scenes.limits.Limits``) bounds the memory the scene may need; files are
    also bounded in size, nesting and alias expansion (``core.scenes.yamlfile``).
    """
    path: str | None = None
    if isinstance(source, dict):
        data = source
    elif isinstance(source, os.PathLike) or (isinstance(source, str) and "\n" not in source):
        path = resolve_scene_path(os.fspath(source))
        data = parse_yaml(read_scene_file(path), path)
    elif isinstance(source, str):
        data = parse_yaml(source)
    else:
        raise SceneError(f"scene: expected a file name, YAML text or a mapping, got "
                         f"{type(source).__name__}")
    if overrides:
        data = _apply_overrides(data, overrides)
    scene = build_scene(data, limits)
    scene.path = path
    return scene


def _apply_overrides(data: Any, overrides: dict[str, Any]) -> Any:
    """Set dotted keys (``integrator.dt``) to values; used by the CLI."""
    if not isinstance(data, dict):
        return data                                     # build_scene names the problem
    data = dict(data)
    for key, value in overrides.items():
        if value is None:
            continue
        node = data
        parts = key.split(".")
        for p in parts[:-1]:
            child = node.get(p, {})
            node[p] = dict(child) if isinstance(child, dict) else child
            node = node[p]
            if not isinstance(node, dict):
                break
        else:
            node[parts[-1]] = value
    return data


#: model.representation's values (``so.group_for``)
REPRESENTATIONS = ("auto", "angle", "so3", "so3-cayley", "so3-exp", "matrix")
MODEL_KEYS = ("order", "kappa", "gamma", "mass", "kappa_2", "L", "representation", "centroids")
TOP_KEYS = ("name", "description", "dimension", "seed", "model", "integrator", "time",
            "convergence", "groups", "figure", "graph", "formation", "safety")


def build_scene(data: object, limits: Limits | None = None) -> Scene:
    top = Map(data, "", TOP_KEYS)
    name = top.text("name", "scene")
    description = top.text("description", "")
    dim = top.number("dimension", integer=True, minimum=2, maximum=MAX_DIMENSION)
    seed = top.number("seed", 0, integer=True, minimum=0, maximum=2**63 - 1)
    budget = Budget(limits)
    params = _model_params(Map(top.raw("model", {}), "model", MODEL_KEYS), dim)
    tm = Map(top.raw("time", {}), "time", ("t_end", "samples"))
    t_end = tm.number("t_end", 20.0, minimum=MIN_T_END)
    samples = _samples(tm, t_end)
    budget.charge("time.samples", len(samples) * 2048, f"metrics at {len(samples)} samples")
    spec = _integrator_spec(Map(top.raw("integrator", {}), "integrator",
                                ("method", "dt", "tolerance", "max_steps")), t_end)

    groups, states, ctx = _groups(top, dim, params, seed, budget)
    model = Model(dim=dim, order=params["order"], kappa=params["kappa"], gamma=params["gamma"],
                  mass=params["mass"], groups=tuple(groups), rotations=params["rotations"],
                  kappa_2=params["kappa_2"], L=params["L"], centroids=params["centroids"])
    validate_model(model)
    check_rates("model", model_rates(model))
    formation, safety = _formation_and_safety(top, model, states)
    origin = np.concatenate([gs.x for gs in states]).mean(axis=0)
    for gs in states:
        gs.x = gs.x - origin
    cm = Map(top.raw("convergence", {}), "convergence", ("tolerance", "expected"))
    conv_tol = cm.number("tolerance", 1e-6, positive=True, maximum=MAX_LENGTH)
    expected = cm.flag("expected", True)
    fm = Map(top.raw("figure", {}), "figure", ("snapshots",))
    snaps = vector(fm.raw("snapshots", [0, 3, 6, 12]), "figure.snapshots")
    snapshots = tuple(float(t) for t in snaps if 0 <= t <= t_end)
    return Scene(name=name, description=description, model=model,
                 initial=State(0.0, tuple(states)), origin=origin, integrator=spec, t_end=t_end,
                 samples=samples, snapshots=snapshots, tolerance=conv_tol,
                 expect_convergence=expected, seed=seed, notes=ctx.notes, formation=formation,
                 safety=safety)


def _formation_and_safety(top: Map, model: Model,
                          states: list) -> tuple[np.ndarray | None, SafetySpec | None]:
    """The scene's formation offsets (the initial centroids become x_i - c_i, in place) and
    its safety spec; refuses a formation whose places are closer than 2 safety.radius."""
    safety = parse_safety(top.raw("safety")) if top.has("safety") else None
    if not top.has("formation"):
        return None, safety
    if model.inter_group or any(g.graph is not None and g.graph.dynamic for g in model.groups):
        raise SceneError("formation: not with an inter-group potential (kappa_2) or a proximity "
                         "graph: both act on the distances between centroids, not on x_i - c_i")
    sizes = {g.name: (g.start, g.size) for g in model.groups}
    offsets = parse_formation(top.raw("formation"), model.dim, sizes)
    if safety is not None:
        check_separation(offsets, safety.radius)
    for g, gs in zip(model.groups, states):
        gs.x = gs.x - offsets[g.start:g.start + g.size]
    return offsets, safety


def _model_params(mm, dim):
    order = mm.number("order", 1, integer=True)
    if order not in (1, 2):
        raise SceneError(f"model.order: must be 1 (A-2) or 2 (A-1), got {order}")
    out = {"order": order}
    for key, default in (("kappa", 1.0), ("gamma", 1.0), ("mass", 0.0 if order == 1 else 1.0),
                         ("kappa_2", 0.0)):
        out[key] = mm.number(key, default, minimum=0, maximum=MAX_RATE)
    if order == 1 and out["mass"] != 0:
        raise SceneError(f"model.mass: the first-order model (A-2) has m = 0, got {out['mass']}; "
                         f"set order: 2")
    out["L"] = mm.number("L", 0.0, minimum=0, maximum=MAX_LENGTH)
    out["has_L"] = mm.has("L")
    representation = mm.text("representation", "auto")
    if representation not in REPRESENTATIONS:
        raise SceneError(f"model.representation: unknown rotation representation "
                         f"{representation!r}{did_you_mean(representation, REPRESENTATIONS)} "
                         f"(allowed: {', '.join(REPRESENTATIONS)})")
    try:
        out["rotations"] = group_for(dim, representation)
    except ValueError as exc:
        raise SceneError(f"model.representation: {exc}") from None
    out["centroids"] = mm.text("centroids", "exact")
    if out["centroids"] not in ("exact", "integrated"):
        raise SceneError(f"model.centroids: expected exact or integrated, "
                         f"got {out['centroids']!r}")
    return out


def _groups(top, dim, params, seed, budget):
    raw_groups = top.raw("groups")
    if raw_groups is None:
        raise SceneError("groups: required, a list of groups (each '- shape: ..., count: ...')")
    if not isinstance(raw_groups, list):
        raise SceneError(f"groups: expected a list of groups (each '- shape: ...'), "
                         f"got {describe(raw_groups)}")
    if not raw_groups:
        raise SceneError("groups: empty; give at least one group")
    ctx = GroupContext(dim, params["order"], np.random.default_rng(seed), params["rotations"],
                       budget)
    groups, states, names = [], [], set()
    for gi, raw in enumerate(raw_groups):
        g, gs = build_group(raw, f"groups[{gi}]", ctx)
        if g.name in names:
            raise SceneError(f"groups[{gi}].name: duplicate group name {g.name!r}")
        names.add(g.name)
        groups.append(g)
        states.append(gs)
        ctx.start += g.size
    # communication graphs: core.graph parses and validates the scene's and each group's `graph`
    for gi, (raw, g) in enumerate(zip(raw_groups, groups)):
        spec = raw.get("graph") if isinstance(raw, dict) else None
        spec = spec if spec is not None else top.raw("graph")
        if isinstance(spec, dict) and "radius" in spec:
            # a proximity graph holds only the pairs in range, but a team that closes up has
            # every pair in range: N (N - 1) weights (pairs, distances, weights, sparse rows)
            budget.charge(f"groups[{gi}].graph", BYTES_PER_WEIGHT * float(g.size) ** 2,
                          f"up to {g.size} x {g.size} proximity weights, every pair in range")
        elif spec not in (None, "complete"):
            # adjacency, Laplacian and its eigenmodes are dense N x N (a few copies)
            budget.charge(f"groups[{gi}].graph", 4.0 * FLOAT * float(g.size) ** 2,
                          f"a {g.size} x {g.size} graph Laplacian and its eigenmodes")
    graphs = graph.group_graphs(top.raw("graph"), raw_groups, [g.size for g in groups],
                                [gs.x for gs in states])
    groups = [replace(g, graph=gr) for g, gr in zip(groups, graphs)]
    if (params["kappa_2"] > 0 or params["has_L"]) and len(groups) == 1:
        ctx.notes.append("one group: the inter-group potential (kappa_2, L) has nothing to act on "
                         "and is not modelled")
        params["kappa_2"] = 0.0
    return groups, states, ctx


def model_rates(model: Model) -> list[tuple[str, float]]:
    """(name, 1/s) of the linearisation at consensus: coupling, damping, F-1 weights, F-2."""
    m, gamma, k = model.mass, model.gamma, model.kappa
    weight = max([1.0] + [float(np.mean(g.scales) / np.min(g.scales))
                          for g in model.groups if g.scales is not None])
    fastest = k * weight + model.kappa_2
    if model.order == 1:
        return [("(kappa * max s_k/s_i + kappa_2) / gamma", fastest / gamma)]
    return [("(kappa * max s_k/s_i + kappa_2) / m", fastest / m), ("gamma / m", gamma / m)]


#: what integrator.method and --integrator accept
INTEGRATOR_NAMES = (*sorted(METHODS), "adaptive", "auto")


def _integrator_spec(im, t_end):
    method = im.text("method", "auto")
    if method not in ("auto", "adaptive") and method not in METHODS:
        raise SceneError(f"integrator.method: unknown integrator {method!r}; known: "
                         f"{', '.join(INTEGRATOR_NAMES)}{did_you_mean(method, INTEGRATOR_NAMES)}")
    dt = im.number("dt", 0.0, positive=True) if im.has("dt") else None
    tol = tolerance_value(im.raw("tolerance"), "integrator.tolerance") \
        if im.has("tolerance") else None
    max_steps = im.number("max_steps", 10_000_000, integer=True, minimum=1)
    if method == "adaptive" and dt is not None:
        raise SceneError("integrator.dt: the adaptive method chooses its own steps; give "
                         "integrator.tolerance, or a fixed-step method for dt")
    if method in METHODS and tol is not None:
        raise SceneError(f"integrator.tolerance: {method} takes fixed steps (integrator.dt); "
                         f"a tolerance needs method: adaptive")
    if method in METHODS or dt is not None:
        check_step_count(t_end, dt or DEFAULT_DT, max_steps, "integrator.dt" if dt else
                         "integrator.method")
    return IntegratorSpec(method, dt, tol, max_steps)


def tolerance_value(value: object, path: str) -> float:
    """An adaptive tolerance: relative, in [MIN_RELATIVE_TOLERANCE, 1)."""
    tol = number(value, path)
    if not 0 < tol < 1:
        raise SceneError(f"{path}: must be in (0, 1), got {tol:g}")
    if tol < MIN_RELATIVE_TOLERANCE:
        raise SceneError(f"{path}: {tol:g} is below {MIN_RELATIVE_TOLERANCE:g}, which double "
                         f"precision cannot attain (round-off alone is ~1e-16 per step)")
    return tol


def check_step_count(t_end: float, dt: float, max_steps: int, path: str) -> int:
    """Refuse a fixed-step run whose step count exceeds integrator.max_steps."""
    steps = math.ceil(min(t_end / min(dt, t_end), 1e308) - 1e-9)
    if steps > max_steps:
        raise SceneError(f"{path}: dt = {dt:g} over t_end = {t_end:g} takes {float(steps):.3g} "
                         f"steps, more than integrator.max_steps = {max_steps}")
    return steps


def _samples(tm, t_end):
    """Sample times in [0, t_end], both ends included; times closer than 1e-9 max(1, t_end)
    are merged so no integrator is asked for a step of round-off size."""
    times = _sample_times(tm, t_end)
    gap = 1e-9 * max(1.0, t_end)
    kept = times[np.insert(np.diff(times) > gap, 0, True)]
    kept[-1] = t_end if len(kept) > 1 else kept[-1]
    return kept if len(kept) > 1 else np.array([0.0, t_end])


def _sample_times(tm, t_end):
    path = tm.at("samples")
    raw = tm.raw("samples")
    if raw is None:
        return np.linspace(0.0, t_end, 101)
    if isinstance(raw, dict):
        sm = Map(raw, path, ("every", "count"))
        if sm.has("every") == sm.has("count"):
            raise SceneError(f"{path}: give exactly one of 'every' or 'count'")
        if sm.has("every"):
            every = sm.number("every", positive=True)
            n = t_end / every
            if not n <= MAX_SAMPLES:
                raise SceneError(f"{sm.at('every')}: every {every:g} over t_end = {t_end:g} is "
                                 f"{n:.3g} samples, more than the limit of {MAX_SAMPLES} "
                                 f"samples a run")
            times = every * np.arange(int(math.floor(n + 1e-9)) + 1)
            return np.unique(np.append(times[times <= t_end], t_end))
        count = sm.number("count", integer=True, minimum=2, maximum=MAX_SAMPLES)
        return np.linspace(0.0, t_end, count)
    if not isinstance(raw, list):
        raise SceneError(f"{path}: expected {{every: dt}}, {{count: n}} or a list of times, "
                         f"got {describe(raw)}")
    times = vector(raw, path)
    if np.any(times < 0) or np.any(times > t_end):
        raise SceneError(f"{path}: sample times must lie in [0, t_end = {t_end}]")
    return np.unique(np.concatenate([[0.0], times, [t_end]]))
