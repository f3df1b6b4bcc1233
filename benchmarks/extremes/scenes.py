"""Scenes and measurements of the extremes (shared by the table and the tests).

Scene factories build each extreme's scene at any size; measurements turn a run into the
numbers an expectation is judged on.  ``test/core/test_extremes.py`` builds its scenes here too
and checks the numbers against its own independent oracles.
"""

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

EXPLICIT = ("lie_euler", "lie_heun", "rkmk4", "euler_proj", "rk4_proj")
EXTREMES_DIR = Path(__file__).resolve().parents[2] / "config" / "extremes"


@dataclass(frozen=True)
class Variant:
    """Sizes of one rendering: ``quick`` (toy sizes, ``--quick``) or full."""

    quick: bool = False
    n_large: int = 10_000
    t_long: float = 1e4

    def fields(self):
        """Values the labels and captions of the table name."""
        q = self.quick
        return {"n_large": 200 if q else self.n_large, "t_long": 200.0 if q else self.t_long,
                "t_undamped": 50.0 if q else self.t_long, "n_stiff": 6 if q else 50,
                "t_stiff": 2.0 if q else 10.0, "n_coupling": 6 if q else 100,
                "n_dim10": 4 if q else 100,
                "budget": 300 if q else 20000}


@dataclass(frozen=True)
class Outcome:
    """What happened, whether the expectation held, and rows for the extreme's detail table."""

    happened: str
    ok: bool
    rows: tuple = field(default=())


def scene_data(dim, order=1, *, count=6, seed=1, kappa=1.0, gamma=1.0, mass=0.5, shape=None,
               rotations="uniform", centroids=None, velocities=None, t_end=10.0, samples=None,
               scales=None, representation="auto", kappa_2=None, L=None, integrator=None,
               group_name="g", extra_groups=()):
    """The scene dict (the YAML format of config/*.yaml) of one group of ``count`` polytopes
    (regular d-simplices unless ``shape``), followed by ``extra_groups``.

    The model is (A-1), (A-2), (F-1) or, with ``kappa_2``/``L``, (F-2) as the arguments select."""
    model = {"order": order, "kappa": kappa, "gamma": gamma, "representation": representation}
    if order == 2:
        model["mass"] = mass
    model.update({k: v for k, v in (("kappa_2", kappa_2), ("L", L)) if v is not None})
    group = {"name": group_name, "shape": shape or {"simplex": dim}, "count": count,
             "rotations": rotations,
             "centroids": centroids or {"box": [-2.0, 2.0]}}
    if scales is not None:
        group["scales"] = scales
    if order == 2 and velocities is not None:
        group["velocities"] = velocities
    time = {"t_end": t_end}
    if samples is not None:
        time["samples"] = samples
    data = {"dimension": dim, "seed": seed, "model": model, "time": time,
            "groups": [group, *extra_groups]}
    if integrator is not None:
        data["integrator"] = integrator
    return data


def scene(dim, order=1, *, max_steps=None, **kw):
    """One group of polytopes (``scene_data``'s arguments) -> Scene, with ``max_steps``."""
    from polymatch_ros.core import load_scene
    integrator = None if max_steps is None else {"max_steps": max_steps}
    return load_scene(scene_data(dim, order, integrator=integrator, **kw))


def stiff_mass_scene(order, count, mass=1e-8, **kw):
    """m = 1e-8 (second order) or its first-order limit (A-2): kappa = 1.5, gamma = 2."""
    return scene(3, order, count=count, seed=7, kappa=1.5, gamma=2.0, mass=mass, **kw)


def undamped_scene(t_end, dim=2):
    """gamma = 0, m = kappa = 1, N = 5, angular velocities ~ N(0, 0.7^2), 200 samples."""
    return scene(dim, 2, count=5, seed=11, gamma=0.0, mass=1.0, t_end=t_end,
                 samples={"every": t_end / 200},
                 velocities={"angular": {"normal": 0.7}})


def stiff_coupling_scene(order, count, t_end, **kw):
    """kappa = 1e4, gamma = m = 1."""
    return scene(3, order, count=count, seed=7, kappa=1e4, mass=1.0, t_end=t_end, **kw)


def scale_ratio_scene(order, t_end=1.0, **kw):
    """Similar ensemble (F-1), scales log-uniform in 1e-6 .. 1e6, N = 6 triangles."""
    return scene(2, order, count=6, seed=5, scales={"log_uniform": [1e-6, 1e6]}, mass=0.5,
                 t_end=t_end,
                 shape="triangle", **kw)


def grid_points(rng, count, dim):
    """Points in [-5, 5]^d on a 2^-10 grid: exactly representable next to 1e9 too."""
    return np.round(rng.uniform(-5, 5, (count, dim)) * 2 ** 10) / 2 ** 10


def placed_scene(offset, pa, pb, dim, order, kappa_2=None, t_end=20.0, shape_b="square"):
    """Triangles at centroids ``pa + offset``; with ``kappa_2`` also a second group at
    ``pb + offset``."""
    from polymatch_ros.core import load_scene
    model = {"order": order, "kappa": 1.0, "gamma": 1.0}
    if order == 2:
        model["mass"] = 0.5
    groups = [{"name": "a", "shape": "triangle", "count": len(pa), "rotations": "uniform",
               "centroids": {"points": (pa + offset).tolist()}}]
    if kappa_2:
        model.update(kappa_2=kappa_2, L=3.0)
        groups.append({"name": "b", "shape": shape_b, "count": len(pb), "rotations": "uniform",
                       "centroids": {"points": (pb + offset).tolist()}})
    return load_scene({"dimension": dim, "seed": 4, "model": model,
                       "time": {"t_end": t_end, "samples": {"every": 0.5}}, "groups": groups})


def explicit_triangles_at(offset):
    """Three triangles given by explicit vertices around ``offset`` (a scene dict)."""
    tri = np.array([[0.0, 1.0], [-math.sqrt(3) / 2, -0.5], [math.sqrt(3) / 2, -0.5]])
    agents = []
    for a, c in ((0.3, (0.0, 0.0)), (1.2, (3.0, -2.0)), (2.0, (-1.0, 4.0))):
        rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
        agents.append({"vertices": (tri @ rot.T + np.array(c) + offset).tolist()})
    return {"dimension": 2, "groups": [{"name": "g", "shape": "triangle", "agents": agents}]}


def coincident_scene(order, at=(0.0, 0.0), t_end=20.0, every=1.0):
    """config/extremes/coincident_mixed.yaml (F-2) with every centroid at ``at``."""
    import yaml

    from polymatch_ros.core import load_scene
    data = yaml.safe_load((EXTREMES_DIR / "coincident_mixed.yaml").read_text())
    data["model"]["order"] = order
    if order == 1:
        data["model"].pop("mass")
    for g in data["groups"]:
        g["centroids"] = {"at": list(at)}
    data["time"] = {"t_end": t_end, "samples": {"every": every}}
    return load_scene(data)


def coincident_pairs_scene(offset, t_end=20.0):
    """Each centroid of group a on one of group b (so the group centres coincide), around
    ``offset``."""
    pts = grid_points(np.random.default_rng(3), 6, 2)
    return placed_scene(offset, pts, pts[::-1], 2, 2, kappa_2=0.5, t_end=t_end)


def collinear_agents(dim, height, count=5, seed=0):
    """Vertices (count, 3, d) of triangles of length 1 and height ``height``; their rotations."""
    rng = np.random.default_rng(seed)
    tri = np.zeros((3, dim))
    tri[1, 0], tri[2, 0], tri[2, 1] = 1.0, 0.5, height
    if dim == 2:
        a = rng.uniform(-np.pi, np.pi, count)
        rots = np.stack([np.stack([np.cos(a), -np.sin(a)], -1), np.stack([np.sin(a), np.cos(a)],
                                                                         -1)], -2)
    else:
        from scipy.spatial.transform import Rotation
        rots = Rotation.random(count, random_state=1).as_matrix()
    cents = rng.uniform(-3.0, 3.0, (count, dim))
    return np.einsum("nij,aj->nai", rots, tri) + cents[:, None, :], rots


def collinear_scene(dim, verts, order=1, every=5.0):
    from polymatch_ros.core import load_scene
    model = {"order": order} if order == 1 else {"order": 2, "mass": 0.5}
    return load_scene({"dimension": dim, "model": model, "time": {"t_end": 40.0,
                                                                  "samples": {"every": every}},
                       "groups": [{"name": "slivers",
                                   "agents": [{"vertices": v.tolist()} for v in verts]}]})


# ---------------------------------------------------------------------------------------------
# measurements


def refusal_limit(exc):
    """The stable-step limit a StabilityError names (its ``limit``; None if none or no error)."""
    return getattr(exc, "limit", None)


def refusal(scene_, method, dt):
    """The StabilityError a fixed-step run raises before stepping, or None if it runs."""
    from polymatch_ros.core import StabilityError, simulate
    try:
        simulate(scene_, method, dt, keep_states=False, metrics=False, samples=[0.0])
    except StabilityError as exc:
        return exc
    return None


def rk_stability_limit(order, eigenvalues):
    """Largest h with |R(h lambda)| <= 1 for R(z) = sum_{k <= order} z^k / k!.

    R is the stability polynomial of explicit RK of orders 1, 2 and 4."""
    coefs = [1.0 / math.factorial(k) for k in range(order + 1)]

    def stable(h):
        return all(abs(np.polyval(coefs[::-1], h * lam)) <= 1.0 for lam in eigenvalues)

    lo, hi = 0.0, 100.0 / max(abs(lam) for lam in eigenvalues)
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if stable(mid) else (lo, mid)
    return lo


def finite(traj):
    """Every sampled state and metric of a trajectory is finite."""
    for st in list(traj.states) + [traj.final]:
        for gs in st.groups:
            for a in (gs.x, gs.v, gs.w, gs.rot):
                if a is not None and not np.all(np.isfinite(np.asarray(a))):
                    return False
    return all(np.isfinite(m.diameter) for m in traj.metrics)


def max_error(scene_a, a, scene_b, b):
    """max |O_a - O_b| and |xbar_a - xbar_b| over the agents of two states."""
    ra, rb = scene_a.model.rotations, scene_b.model.rotations
    err = 0.0
    for ga, gb in zip(a.groups, b.groups):
        err = max(err, float(np.max(np.abs(ra.to_matrices(ga.rot) - rb.to_matrices(gb.rot)))),
                  float(np.max(np.abs(ga.x - gb.x))))
    return err


def defect(scene_, state):
    """Lemma 2.1's orthogonality defect of the first group."""
    from polymatch_ros.core.metrics import orthogonality_defect
    return orthogonality_defect(scene_.model.rotations, state.groups[0].rot)


def antipodal_deviation(rep, state):
    """pi minus the angle of O_1^T O_2, from sin(angle) = |R - R^T|_F / (2 sqrt 2).

    Accurate near pi, where the angle itself is ill-conditioned."""
    mats = rep.to_matrices(state.groups[0].rot)
    r = mats[0].T @ mats[1]
    return float(np.arcsin(min(1.0, np.linalg.norm(r - r.T) / (2 * math.sqrt(2)))))


def splay_deviation(rep, state):
    """Distance of the angles from an evenly spaced (splay) set, up to a common rotation."""
    mats = rep.to_matrices(state.groups[0].rot)
    th = np.arctan2(mats[:, 1, 0], mats[:, 0, 0])
    dev = np.angle(np.exp(1j * (th - th[0] - 2 * np.pi * np.arange(len(th)) / len(th))))
    return float(np.linalg.norm(dev - dev.mean()))


#: name: (label, d, shape, rotations, deviation,
#:        linear rate of the unstable mode at first order / kappa)
EQUILIBRIA = {
    "antipodal_2d": ("antipodal SO(2)", 2, "triangle", {"angles": [0.0, math.pi]},
                     antipodal_deviation, 1.0),
    "antipodal_3d": ("antipodal SO(3)", 3, "tetrahedron", {"rotvecs": [[0, 0, 0], [0, 0,
                                                                                   math.pi]]},
                     antipodal_deviation, 1.0),
    "splay_2d": ("splay SO(2), N = 3", 2, "triangle", {"angles": [0.0, 2 * math.pi / 3,
                                                                  4 * math.pi / 3]},
                 splay_deviation, 0.5),
}


def equilibrium_run(name, order, rep, t_rates, every, m=0.5, gamma=1.0, dt=0.05):
    """Run an equilibrium for ``t_rates`` e-folding times (rkmk4 at ``dt``).

    Returns (scene, traj, times, deviations, rate)."""
    from polymatch_ros.core import simulate
    _label, dim, shape, rots, deviation, c = EQUILIBRIA[name]
    rate = c if order == 1 else (-gamma + math.sqrt(gamma ** 2 + 4 * m * c)) / (2 * m)
    sc = scene(dim, order, count=len(next(iter(rots.values()))), shape=shape, rotations=rots,
               representation=rep, mass=m, gamma=gamma, t_end=t_rates / rate,
               samples={"every": every},
               centroids={"box": [-1.0, 1.0]})
    traj = simulate(sc, "rkmk4", dt)
    eps = np.array([deviation(sc.model.rotations, st) for st in traj.states])
    return sc, traj, np.array(traj.times), eps, rate
