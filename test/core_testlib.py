"""Independent helpers for the core test-suite (test_core_*.py).

Everything here is written from the paper's formulas and the documented array
layouts, *not* by calling the core's own conversion or metric code, so the
tests compare the core against an independent computation.
"""

from itertools import combinations

import numpy as np
from scipy.spatial.distance import pdist

from polymatch_ros.core import load_scene

J2 = np.array([[0.0, -1.0], [1.0, 0.0]])


def rot_matrices(rep, g):
    """(N, d, d) rotation matrices from a group array, from the documented layouts."""
    if rep.name == "angle":                      # angles theta (N,)
        c, s = np.cos(g), np.sin(g)
        out = np.empty((len(g), 2, 2))
        out[:, 0, 0], out[:, 0, 1], out[:, 1, 0], out[:, 1, 1] = c, -s, s, c
        return out
    if rep.name == "so3":                        # structure of arrays (3, 3, N)
        return np.moveaxis(np.asarray(g), 2, 0).copy()
    if rep.name == "matrix":                     # (N, d, d)
        return np.array(g, dtype=float)
    raise AssertionError(f"unknown representation {rep.name}")


def skew_matrices(rep, a):
    """(N, d, d) skew matrices hat(a) from an algebra array."""
    if rep.name == "angle":                      # scalars w, hat(w) = w J
        return np.asarray(a)[:, None, None] * J2
    if rep.name == "so3":                        # vectors (3, N)
        x, y, z = np.asarray(a)
        out = np.zeros((x.shape[0], 3, 3))
        out[:, 0, 1], out[:, 0, 2], out[:, 1, 2] = -z, y, -x
        out[:, 1, 0], out[:, 2, 0], out[:, 2, 1] = z, -y, x
        return out
    if rep.name == "matrix":
        return np.array(a, dtype=float)
    raise AssertionError(f"unknown representation {rep.name}")


def defect(mats):
    """max_i |O_i^T O_i - I|_F (Lemma 2.1)."""
    d = mats.shape[1]
    gram = np.einsum("nki,nkj->nij", mats, mats)
    return float(np.max(np.linalg.norm(gram - np.eye(d), axis=(1, 2))))


def brute_diameter(points):
    """max_{i,j} |p_i - p_j| by scipy's pdist (independent of metrics.point_set_diameter)."""
    p = np.asarray(points, dtype=float).reshape(len(points), -1)
    return float(pdist(p).max()) if len(p) > 1 else 0.0


def brute_rotation_diameter(mats):
    """max_{i,j} |O_i - O_j|_F over explicit pairs."""
    pairs = combinations(range(len(mats)), 2)
    return max((float(np.linalg.norm(mats[i] - mats[j])) for i, j in pairs), default=0.0)


def vertices(model, state, gi):
    """(N, n, d) vertices x^i_a = xbar^i + s^i O^i r_a of group gi."""
    grp = model.groups[gi]
    gs = state.groups[gi]
    mats = rot_matrices(model.rotations, gs.rot)
    s = np.ones(len(mats)) if grp.scales is None else np.asarray(grp.scales)
    return gs.x[:, None, :] + s[:, None, None] * np.einsum("nij,aj->nai", mats, grp.reference)


def brute_matching_diameter(model, state, gi):
    """max_{i,j,a} |x^i_a - x^j_a|, brute force over pairs of polytopes and vertices."""
    v = vertices(model, state, gi)
    best = 0.0
    for i, j in combinations(range(v.shape[0]), 2):
        best = max(best, float(np.max(np.linalg.norm(v[i] - v[j], axis=1))))
    return best


def rotation_energy(model, gs):
    """E = (m/N) sum |O_i'|^2 + kappa/(2N^2) sum_{i,k} |O_i - O_k|^2 with O_i' = W_i O_i
    (Prop. 2.2 i)."""
    rep = model.rotations
    mats = rot_matrices(rep, gs.rot)
    n = len(mats)
    kinetic = 0.0
    if gs.w is not None:
        odot = np.einsum("nij,njk->nik", skew_matrices(rep, gs.w), mats)
        kinetic = model.mass / n * float(np.sum(odot * odot))
    diff = mats[:, None] - mats[None, :]
    return kinetic + model.kappa / (2.0 * n * n) * float(np.sum(diff * diff))


def state_error(scene_a, state_a, scene_b, state_b):
    """Per-component max errors between two states: {'rot', 'w', 'x', 'v'} (matrices compared)."""
    out = {"rot": 0.0, "w": 0.0, "x": 0.0, "v": 0.0}
    ra, rb = scene_a.model.rotations, scene_b.model.rotations
    for ga, gb in zip(state_a.groups, state_b.groups):
        rot_diff = rot_matrices(ra, ga.rot) - rot_matrices(rb, gb.rot)
        out["rot"] = max(out["rot"], float(np.max(np.abs(rot_diff))))
        out["x"] = max(out["x"], float(np.max(np.abs(ga.x - gb.x))))
        if ga.v is not None and gb.v is not None:
            out["v"] = max(out["v"], float(np.max(np.abs(ga.v - gb.v))))
        if ga.w is not None and gb.w is not None:
            w_diff = skew_matrices(ra, ga.w) - skew_matrices(rb, gb.w)
            out["w"] = max(out["w"], float(np.max(np.abs(w_diff))))
    return out


def make_scene(dim, order=1, *, count=4, seed=1, representation="auto", kappa=1.0, gamma=1.0,
               mass=0.5, shape=None, rotations="uniform", velocities=None, t_end=1.0,
               samples=None, scales=None, method="rkmk4", dt=0.01, extra_groups=(), kappa_2=None,
               L=None, centroids=None):
    """An inline scene dict -> Scene (the YAML format of config/*.yaml)."""
    model = {"order": order, "kappa": kappa, "gamma": gamma, "representation": representation}
    if order == 2:
        model["mass"] = mass
    if kappa_2 is not None:
        model["kappa_2"] = kappa_2
    if L is not None:
        model["L"] = L
    group = {"name": "g0", "shape": shape or {"simplex": dim}, "count": count,
             "rotations": rotations, "centroids": centroids or {"box": [-2.0, 2.0]}}
    if scales is not None:
        group["scales"] = scales
    if order == 2 and velocities is not None:
        group["velocities"] = velocities
    time = {"t_end": t_end}
    if samples is not None:
        time["samples"] = samples
    return load_scene({"dimension": dim, "seed": seed, "model": model,
                       "integrator": {"method": method, "dt": dt}, "time": time,
                       "groups": [group] + list(extra_groups)})
