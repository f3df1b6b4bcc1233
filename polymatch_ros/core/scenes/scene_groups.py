"""One group of a scene: its reference polytope and the initial states of its agents (Section 3).

Either generated (``shape`` + ``count`` + centroid, rotation, scale and velocity draws) or
explicit (``agents: [{vertices: ...}]``, decomposed as x^i_a = xbar^i + s^i O^i r_a).
Every size is charged to the scene's memory ``Budget`` before it is allocated.
"""

import warnings
from dataclasses import dataclass, field

import numpy as np

from ..errors import SceneError
from ..model import Group, GroupState
from ..so import RotationGroup
from . import initial
from .checks import Map, describe
from .decompose import RotationNotUniqueWarning, decompose
from .limits import MAX_LENGTH, MIN_SIZE, Budget
from .shapes import check_vertex_array, make_shape

GROUP_KEYS = ("name", "shape", "size", "count", "centroids", "rotations", "scales",
              "velocities", "agents", "similar", "graph")


@dataclass
class GroupContext:
    """What every group of a scene shares while it is built."""

    dim: int
    order: int
    rng: np.random.Generator
    rotations: RotationGroup
    budget: Budget
    notes: list[str] = field(default_factory=list)
    start: int = 0


def build_group(raw: object, path: str, ctx: GroupContext) -> tuple[Group, GroupState]:
    """(Group, GroupState) of one ``groups[i]`` entry."""
    gm = Map(raw, path, GROUP_KEYS)
    name = gm.text("name", f"group{ctx.start}")
    explicit = gm.has("agents")
    if explicit:
        for key in ("count", "centroids", "rotations", "scales"):
            if gm.has(key):
                raise SceneError(f"{gm.at(key)}: not allowed together with 'agents' "
                                 f"(explicit vertices)")
    similar = gm.flag("similar", gm.has("scales"))
    size = gm.number("size", 1.0, minimum=MIN_SIZE, maximum=MAX_LENGTH)
    shape = None
    if gm.has("shape"):
        shape = make_shape(gm.raw("shape"), gm.at("shape"), max_dim=ctx.dim)
        if shape.dim > ctx.dim:
            raise SceneError(f"{gm.at('shape')}: shape {shape.name!r} lives in R^{shape.dim}, "
                             f"the scene has dimension {ctx.dim}")
        shape = shape.embedded(ctx.dim).scaled(size)
    elif not explicit:
        raise SceneError(f"{gm.at('shape')}: required (or give explicit 'agents' with vertices)")
    if explicit:
        return _explicit_group(gm, name, shape, similar, ctx)
    return _generated_group(gm, name, shape, similar, ctx)


def _explicit_group(gm, name, shape, similar, ctx):
    agents = gm.raw("agents")
    apath = gm.at("agents")
    if not isinstance(agents, list) or not agents:
        raise SceneError(f"{apath}: expected a non-empty list of {{vertices: ...}}, "
                         f"got {describe(agents)}")
    verts, vels, omegas = [], [], []
    for ai, a in enumerate(agents):
        am = Map(a, f"{apath}[{ai}]", ("vertices", "velocity", "angular_velocity"))
        if not am.has("vertices"):
            raise SceneError(f"{am.at('vertices')}: required")
        verts.append(check_vertex_array(am.raw("vertices"), am.at("vertices"), ctx.dim))
        vels.append(am.raw("velocity"))
        omegas.append(am.raw("angular_velocity"))
    ctx.budget.charge_agents(apath, len(verts), len(verts[0]), ctx.dim, ctx.order)
    if shape is None:
        shape = make_shape({"vertices": verts[0].tolist()}, f"{apath}[0]")
    ref = shape.vertices
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", RotationNotUniqueWarning)
        cents, mats, scales = decompose(verts, ref, similar=similar, label=f"{apath}: polytope")
    ctx.notes.extend(str(w.message) for w in caught)
    if similar:
        if not np.all((scales >= MIN_SIZE) & (scales <= 1.0 / MIN_SIZE)):
            raise SceneError(f"{apath}: the polytopes' scales span {scales.min():.3g} .. "
                             f"{scales.max():.3g}, beyond [{MIN_SIZE:g}, {1 / MIN_SIZE:g}]")
        s0 = scales.mean()
        ref, scales = ref * s0, scales / s0
        shape = type(shape)(shape.name, ref, shape.edges)
    count = len(verts)
    rot = ctx.rotations.from_matrices(mats)
    v = initial.explicit_vectors(vels, apath, "velocity", ctx.dim, ctx.order)
    w = initial.explicit_omegas(omegas, apath, ctx.dim, ctx.order, ctx.rotations)
    if ctx.order == 1 and (v is not None or w is not None):
        raise SceneError(f"{apath}: velocities are only meaningful for model.order = 2")
    if ctx.order == 2:
        v = np.zeros((count, ctx.dim)) if v is None else v
        w = ctx.rotations.algebra_zeros(count) if w is None else w
    group = Group(name, count, shape.vertices, shape.edges, scales if similar else None,
                  ctx.start)
    return group, GroupState(cents, rot, v, w)


def _generated_group(gm, name, shape, similar, ctx):
    path, dim, rng = gm.path, ctx.dim, ctx.rng
    count = gm.number("count", integer=True, minimum=1)
    ctx.budget.charge_agents(gm.at("count"), count, len(shape.vertices), dim, ctx.order)
    if shape.rank < dim:
        ctx.notes.append(
            f"{path}: shape {shape.name!r} spans {shape.rank} of {dim} dimensions "
            f"(Lemma 3.2 assumes {dim}); "
            + ("its rotation is still unique (det +1 fixes the normal)" if shape.rank == dim - 1
               else "rotations that differ only in the complement leave its vertices in place"))
    cents = initial.centroids(gm.raw("centroids", {"box": [-5.0, 5.0]}), gm.at("centroids"),
                              dim, count, rng)
    mats = initial.rotations(gm.raw("rotations", "uniform"), gm.at("rotations"), dim, count, rng)
    scales = None
    if similar:
        if not gm.has("scales"):
            raise SceneError(f"{gm.at('scales')}: required when similar is true")
        scales = initial.scales(gm.raw("scales"), gm.at("scales"), count, rng)
    if ctx.order == 1 and gm.has("velocities"):
        raise SceneError(f"{gm.at('velocities')}: only meaningful for model.order = 2")
    v = w = None
    if ctx.order == 2:
        v, wm = initial.velocities(gm.raw("velocities", {}), gm.at("velocities"), dim, count, rng)
        w = ctx.rotations.algebra_from_skew(wm)
    group = Group(name, count, shape.vertices, shape.edges, scales, ctx.start)
    return group, GroupState(cents, ctx.rotations.from_matrices(mats), v, w)
