"""Scene loading: initial data satisfy the paper's constraints; bad scenes give one-line
key-path errors."""

from pathlib import Path

import numpy as np
import pytest
from core_testlib import defect, rot_matrices, skew_matrices

from polymatch_ros.core import SceneError, load_scene
from polymatch_ros.core.scenes.shapes import polygon

CONFIG = Path(__file__).resolve().parents[2] / "config"
TRI = polygon(3).vertices


def _base(**over):
    data = {"dimension": 2, "seed": 1, "model": {"order": 1, "kappa": 1.0, "gamma": 1.0},
            "groups": [{"shape": "triangle", "count": 3}]}
    for key, value in over.items():
        data[key] = value
    return data


def _group(**kw):
    g = {"shape": "triangle", "count": 3}
    g.update(kw)
    return g


MODEL_CASES = [
    ("model.order", _base(model={"order": 3})),
    ("model.mass", _base(model={"order": 2, "mass": 0.0})),              # needs m > 0
    ("model.mass", _base(model={"order": 1, "mass": 0.5})),              # has m = 0
    ("model.gamma", _base(model={"order": 1, "gamma": 0.0})),            # divides by gamma
    ("model.kappa", _base(model={"kappa": -1.0})),
    ("model.kappa", _base(model={"kappa": "nan"})),
    ("model.representation", _base(model={"representation": "so3"})),
    ("model.kapa", _base(model={"kapa": 1.0})),
    ("dimension", _base(dimension=1)),
]

GROUP_CASES = [
    ("groups", _base(groups=[])),
    ("groups[0].count", _base(groups=[_group(count=0)])),
    ("groups[0].count", _base(groups=[_group(count=2.5)])),
    ("groups[0].rotations", _base(groups=[_group(rotations="sideways")])),
    ("groups[0].rotations.within", _base(groups=[_group(rotations={"within": -1.0})])),
    ("groups[0].rotations.matrices[0]",
     _base(groups=[_group(rotations={"matrices": [[[1, 0], [0, -1]]] * 3})])),
    ("groups[1].shape", _base(groups=[_group(), _group(name="b", shape="dodecagonal-blob")])),
    ("groups[0].shape", _base(groups=[_group(shape="tetrahedron")])),
    ("groups[0].shape.vertices", _base(groups=[_group(shape={"vertices": [[0.0, 0.0]]})])),
    ("groups[0].velocities", _base(groups=[_group(velocities={"angular": {"normal": 1.0}})])),
    ("groups[0].scales.uniform", _base(groups=[_group(scales={"uniform": [-1.0, 2.0]})])),
    ("groups[0].centroids.points", _base(groups=[_group(centroids={"points": [[0.0, 0.0]]})])),
    ("groups[0].agents", _base(groups=[{"agents": [{"vertices": TRI.tolist()},
                                                   {"vertices": (TRI * [1.0, -1.0]).tolist()}]}])),
    ("groups[0].agents", _base(groups=[{"agents": [{"vertices": TRI.tolist()},
                                                   {"vertices": (TRI * 1.2).tolist()}]}])),
]

RUN_CASES = [
    ("integrator.dt", _base(integrator={"dt": -0.1})),
    ("integrator.dt", _base(integrator={"dt": "fast"})),
    ("integrator.tolerance", _base(integrator={"tolerance": 2.0})),
    ("time.t_end", _base(time={"t_end": 0})),
    ("time.samples", _base(time={"t_end": 5.0, "samples": [1.0, 9.0]})),
]


def _check(path, data):
    with pytest.raises(SceneError) as exc:
        load_scene(data)
    msg = str(exc.value)
    assert msg.startswith(path + ":"), msg
    assert "\n" not in msg and len(msg) < 300
    return msg


@pytest.mark.parametrize("path,data", MODEL_CASES,
                         ids=[f"{c[0]}-{i}" for i, c in enumerate(MODEL_CASES)])
def test_scene_rejects_invalid_model_parameters_A_1_A_2(path, data):
    _check(path, data)


@pytest.mark.parametrize("path,data", GROUP_CASES,
                         ids=[f"{c[0]}-{i}" for i, c in enumerate(GROUP_CASES)])
def test_scene_rejects_invalid_polytope_groups_section_3(path, data):
    msg = _check(path, data)
    if "agents" in path:
        assert ("mirror" in msg) or ("not congruent" in msg)


@pytest.mark.parametrize("path,data", RUN_CASES,
                         ids=[f"{c[0]}-{i}" for i, c in enumerate(RUN_CASES)])
def test_scene_rejects_invalid_integration_settings_section_5(path, data):
    _check(path, data)


@pytest.mark.parametrize("path", sorted(CONFIG.glob("*.yaml")), ids=lambda p: p.stem)
def test_config_initial_data_satisfy_constraints_B_4(path):
    """O^{i0} in SO(d) (B-4), centroids stored as offsets from their mean (the angular
    velocities, O'^{i0} O^{i0 T} = W^{i0}: test_explicit_angular_velocities_are_the_hat_map)."""
    scene = load_scene(path)
    rep = scene.model.rotations
    offsets = np.concatenate([gs.x for gs in scene.initial.groups])
    np.testing.assert_allclose(offsets.mean(axis=0), 0.0, atol=1e-12)
    for g, gs in zip(scene.model.groups, scene.initial.groups):
        mats = rot_matrices(rep, gs.rot)
        assert mats.shape == (g.size, scene.dim, scene.dim)
        assert defect(mats) <= 1e-12
        assert np.all(np.linalg.det(mats) > 0)
        np.testing.assert_allclose(g.reference.mean(axis=0), 0.0, atol=1e-12)   # sum_a r_a = 0
        if scene.model.order == 2:
            assert gs.v.shape == gs.x.shape and gs.w is not None
        else:
            # carries no velocities
            assert gs.v is None and gs.w is None


# a regular tetrahedron of vertex radius 1 (a shape's vertices are scaled to radius 1)
TETRA = np.array([[1.0, 1.0, 1.0], [1.0, -1.0, -1.0], [-1.0, 1.0, -1.0],
                  [-1.0, -1.0, 1.0]]) / np.sqrt(3.0)


@pytest.mark.parametrize("dim", [2, 3])
def test_explicit_angular_velocities_are_the_hat_map(dim):
    """An agent given angular_velocity w starts with O' O^T = W = hat(w), skew (B-4): in 3-D
    W a = w x a for every a (numpy's cross product), in 2-D W = [[0, -w], [w, 0]]."""
    shape = TRI if dim == 2 else TETRA
    rng = np.random.default_rng(dim)
    omegas = rng.normal(size=(3, 1 if dim == 2 else 3))
    agents = [{"vertices": (shape + rng.normal(size=dim)).tolist(),
               "angular_velocity": w.tolist(), "velocity": [0.0] * dim} for w in omegas]
    data = _base(dimension=dim, model={"order": 2, "kappa": 1.0, "gamma": 1.0, "mass": 0.5},
                 groups=[{"shape": {"vertices": shape.tolist()}, "agents": agents}])
    scene = load_scene(data)
    got = skew_matrices(scene.model.rotations, scene.initial.groups[0].w)
    for w, mat in zip(omegas, got):
        np.testing.assert_allclose(mat, -mat.T, rtol=0, atol=0)
        if dim == 2:
            np.testing.assert_allclose(mat, [[0.0, -w[0]], [w[0], 0.0]], rtol=0, atol=1e-15)
        else:
            for a in rng.normal(size=(4, 3)):
                np.testing.assert_allclose(mat @ a, np.cross(w, a), rtol=0, atol=1e-14)


def test_explicit_vertices_round_trip_section_3():
    """A scene given by explicit vertices recovers x^i_a = xbar^i + O^i r_a exactly."""
    rng = np.random.default_rng(4)
    angles = rng.uniform(-np.pi, np.pi, 4)
    cents = rng.normal(scale=3.0, size=(4, 2))
    verts = [c + TRI @ np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]).T
             for a, c in zip(angles, cents)]
    scene = load_scene(_base(groups=[{"shape": {"vertices": TRI.tolist()},
                                      "agents": [{"vertices": v.tolist()} for v in verts]}]))
    gs = scene.initial.groups[0]
    mats = rot_matrices(scene.model.rotations, gs.rot)
    ref = scene.model.groups[0].reference
    rebuilt = scene.origin + gs.x[:, None, :] + np.einsum("nij,aj->nai", mats, ref)
    np.testing.assert_allclose(rebuilt, np.array(verts), atol=1e-12)


# ---------------------------------------------------------------------------------------------
# bounds, tried exactly at and just past each edge (core.scenes.limits, core.scenes.checks,
# core.scenes.scene)


def _simplices(dim, count=2):
    return _base(dimension=dim, groups=[{"shape": {"simplex": dim}, "count": count}])


def _model(order=1, **params):
    model = {"order": order, "kappa": 1.0, "gamma": 1.0}
    model.update(params)
    return _base(model=model)


def _steps(dt):
    """t_end = 1 with at most 10 steps: dt = 0.1 is the smallest step allowed."""
    return _base(integrator={"dt": dt, "max_steps": 10}, time={"t_end": 1.0})


def _adaptive(tolerance):
    return _base(integrator={"method": "adaptive", "tolerance": tolerance})


ACCEPTED_EDGES = [
    ("dimension 2", _simplices(2)),
    ("dimension 64", _simplices(64)),
    ("dimension 64.0", _simplices(64.0)),
    ("count 1", _base(groups=[_group(count=1)])),
    ("count 1.0", _base(groups=[_group(count=1.0)])),
    ("t_end 1e-12", _base(time={"t_end": 1e-12})),
    ("dt 0.1 = t_end / max_steps", _steps(0.1)),
    ("dt > t_end", _steps(2.0)),
    ("tolerance 1e-14", _adaptive(1e-14)),
    ("tolerance 0.999999", _adaptive(0.999999)),
    ("kappa 0", _model(kappa=0.0)),
    ("kappa 1e15", _model(kappa=1e15)),
    ("gamma 1e-15 (kappa / gamma = 1e15)", _model(gamma=1e-15)),
    ("mass 1e-15 (kappa / m = 1e15)", _model(2, mass=1e-15)),
    ("mass 1e15", _model(2, mass=1e15)),
    ("first-order mass 0", _model(1, mass=0.0)),
    ("convergence.tolerance 1e12", _base(convergence={"tolerance": 1e12})),
]

REFUSED_EDGES = [
    ("dimension", "must be <= 64, got 65", _simplices(65)),
    ("dimension", "expected an integer, got 2.5", _simplices(2.5)),
    ("dimension", "must be >= 2, got 1", _simplices(1)),
    ("groups[0].count", "must be >= 1, got 0", _base(groups=[_group(count=0)])),
    ("groups[0].count", "expected an integer, got 1.5", _base(groups=[_group(count=1.5)])),
    ("time.t_end", "must be >= 1e-12, got 9e-13", _base(time={"t_end": 9e-13})),
    ("integrator.dt", "takes 11 steps, more than integrator.max_steps = 10", _steps(0.0999)),
    ("integrator.dt", "must be > 0, got 0.0", _steps(0.0)),
    ("integrator.dt", "must be > 0, got -0.0", _steps(-0.0)),
    ("integrator.dt", "more than integrator.max_steps = 10", _steps(5e-324)),
    ("integrator.tolerance", "9.9e-15 is below 1e-14", _adaptive(9.9e-15)),
    ("integrator.tolerance", "must be in (0, 1), got 1", _adaptive(1.0)),
    ("integrator.tolerance", "must be in (0, 1), got 0", _adaptive(0.0)),
    ("model.kappa", "must be >= 0, got -1e-300", _model(kappa=-1e-300)),
    ("model.kappa", "must be <= 1e+15, got 1e+15", _model(kappa=1.0000001e15)),
    ("model", "the rate (kappa * max s_k/s_i + kappa_2) / gamma = 1.11e+15 exceeds 1e+15/s",
     _model(gamma=9e-16)),
    ("model.gamma", "the first-order model needs gamma > 0, got 0.0", _model(gamma=0.0)),
    ("model", "the rate (kappa * max s_k/s_i + kappa_2) / m = 1.01e+15 exceeds 1e+15/s",
     _model(2, mass=9.9e-16)),
    ("model.mass", "the second-order model needs m > 0, got 0.0", _model(2, mass=0.0)),
    ("model.mass", "must be <= 1e+15, got 1.01e+15", _model(2, mass=1.01e15)),
    ("model.mass", "must be >= 0, got -1e-300", _model(2, mass=-1e-300)),
    ("model.mass", "the first-order model (A-2) has m = 0, got 1e-300", _model(1, mass=1e-300)),
    ("convergence.tolerance", "must be <= 1e+12, got 1.01e+12",
     _base(convergence={"tolerance": 1.01e12})),
    ("convergence.tolerance", "must be > 0, got 0.0", _base(convergence={"tolerance": 0.0})),
]


@pytest.mark.parametrize("label,data", ACCEPTED_EDGES, ids=[c[0] for c in ACCEPTED_EDGES])
def test_scene_accepts_values_exactly_at_its_bounds(label, data):
    scene = load_scene(data)
    assert scene.dim == int(data["dimension"])


@pytest.mark.parametrize("path,words,data", REFUSED_EDGES,
                         ids=[f"{c[0]}: {c[1]}" for c in REFUSED_EDGES])
def test_scene_refuses_values_just_past_its_bounds(path, words, data):
    msg = _check(path, data)
    assert words in msg, msg
