"""Independent helpers for the core test-suite (test_core_*.py).

Everything here is written from the paper's formulas and the documented array
layouts, *not* by calling the core's own conversion or metric code, so the
tests compare the core against an independent computation.
"""

from itertools import combinations

import numpy as np
import yaml
from scipy.spatial.distance import pdist

from benchmarks.extremes.scenes import scene_data
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
    if rep.name == "matrix" and rep.dim == 4 and np.ndim(a) == 2:
        return _so4_hat(np.asarray(a, dtype=float))
    if rep.name == "matrix":
        return np.array(a, dtype=float)
    raise AssertionError(f"unknown representation {rep.name}")


def _hamilton(u, v):
    """Quaternion products u v of (4, N) arrays: (u0 v0 - u.v, u0 v + v0 u + u x v)."""
    return np.concatenate([(u[0] * v[0] - np.sum(u[1:] * v[1:], axis=0))[None],
                           u[0] * v[1:] + v[0] * u[1:] + np.cross(u[1:], v[1:], axis=0)])


def _so4_hat(parts):
    """so(4) held as self-dual parts (6, N) = (a, b) -> (N, 4, 4): W x = a x - x b."""
    n = parts.shape[1]
    a = np.concatenate([np.zeros((1, n)), parts[:3]])
    b = np.concatenate([np.zeros((1, n)), parts[3:]])
    out = np.empty((n, 4, 4))
    for j in range(4):                            # column j: the image of the unit e_j
        e = np.zeros((4, n))
        e[j] = 1.0
        out[:, :, j] = (_hamilton(a, e) - _hamilton(e, b)).T
    return out


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


def make_scene(dim, order=1, *, count=4, t_end=1.0, method="rkmk4", dt=0.01, **kw):
    """An inline scene dict -> Scene (the YAML format of config/*.yaml): one group "g0"
    (``scene_data``'s arguments) integrated by ``method`` at ``dt``."""
    return load_scene(scene_data(dim, order, count=count, t_end=t_end, group_name="g0",
                                 integrator={"method": method, "dt": dt}, **kw))


def agents_of_one_row(sc, method, h, steps, ensemble_for):
    """Every agent a System of its own row (as each lockstep agent is), stepped ``steps`` times
    by ``method``; at each stage agent i is answered with the one-group ensemble
    ``ensemble_for(i, system_i, request_i, rows)`` (``rows``: every agent's stage group state).
    Returns every agent's final state."""
    from polymatch_ros.core.model import GroupState, State, System
    from polymatch_ros.core.stepping.integrators import get_method

    model, grp = sc.model, sc.model.rotations
    n = model.groups[0].size
    systems = [System(model, [[i]]) for i in range(n)]
    g0 = sc.initial.groups[0]
    states = [State(0.0, (GroupState(g0.x[[i]], grp.take(g0.rot, [i]),
                                     None if g0.v is None else g0.v[[i]],
                                     None if g0.w is None else grp.algebra_take(g0.w, [i])),))
              for i in range(n)]
    for _ in range(steps):
        gens = [get_method(method).step(s, st, h) for s, st in zip(systems, states)]
        requests = [next(g) for g in gens]
        done = [None] * n
        while any(d is None for d in done):
            rows = [r.stage.groups[0] for r in requests]
            for i, gen in enumerate(gens):
                if done[i] is None:
                    try:
                        requests[i] = gen.send((ensemble_for(i, systems[i], requests[i],
                                                             rows),))
                    except StopIteration as stop:
                        done[i] = stop.value
        states = [State(d.t, d.groups) for d in done]
    return states


def triangles_yaml(name, *, seed, count, method, dt, t_end, box=3.0, gamma=1.0,
                   rotations="uniform", snapshots=None):
    """The YAML text of a first-order (A-2) scene of ``count`` congruent triangles, kappa = 1,
    centroids uniform in [-box, box]^2: the small scenes the CLI and recording tests run."""
    data = {"name": name, "dimension": 2, "seed": seed,
            "model": {"order": 1, "kappa": 1.0, "gamma": gamma},
            "integrator": {"method": method, "dt": dt}, "time": {"t_end": t_end},
            "groups": [{"name": "triangles", "shape": "triangle", "size": 1.0, "count": count,
                        "centroids": {"box": [-box, box]}, "rotations": rotations}]}
    if snapshots is not None:
        data["figure"] = {"snapshots": snapshots}
    return yaml.safe_dump(data, sort_keys=False)


def lohe_torque(mats, kappa):
    """kappa/(2N) sum_k (O_k O_i^T - O_i O_k^T) for every agent i (the coupling of A-1/A-2)."""
    total = mats.sum(axis=0)
    return kappa / (2 * len(mats)) * (total @ np.swapaxes(mats, 1, 2)
                                       - mats @ total.T)


def written_out_model(scene):
    """The right-hand side of the scene's model, written out from the paper on flat arrays:
    (A-2) gamma O_i' = torque_i O_i, gamma x_i' = kappa/N sum_k (x_k - x_i); (A-1) O_i' = W_i O_i,
    m W_i' = -gamma W_i + torque_i, x_i' = v_i, m v_i' = -gamma v_i + kappa/N sum_k (x_k - x_i)."""
    model = scene.model
    n, d = scene.initial.groups[0].x.shape
    kappa, gamma, mass = model.kappa, model.gamma, model.mass
    sizes = [n * d * d, n * d] + ([n * d * d, n * d] if model.order == 2 else [])

    def rhs(_t, y):
        parts = np.split(y, np.cumsum(sizes)[:-1])
        mats, x = parts[0].reshape(n, d, d), parts[1].reshape(n, d)
        torque = lohe_torque(mats, kappa)
        pull = kappa / n * (x.sum(axis=0) - n * x)
        if model.order == 1:
            return np.concatenate([(torque @ mats).ravel() / gamma, pull.ravel() / gamma])
        w, v = parts[2].reshape(n, d, d), parts[3].reshape(n, d)
        return np.concatenate([(w @ mats).ravel(), v.ravel(),
                               ((torque - gamma * w) / mass).ravel(),
                               ((pull - gamma * v) / mass).ravel()])

    return rhs


def written_out_states(scene, times):
    """The scene's one-group A-1 or A-2 run at ``times``: scipy's DOP853 (``solve_ivp``,
    rtol 3e-14, atol 1e-15) of ``written_out_model`` on the flat rotation matrices, as States in
    the scene's representation (centroid offsets as the scene keeps them)."""
    from scipy.integrate import solve_ivp

    from polymatch_ros.core.model import GroupState, State

    grp, gs = scene.model.rotations, scene.initial.groups[0]
    n, d = gs.x.shape
    second = scene.model.order == 2
    y0 = [rot_matrices(grp, gs.rot).ravel(), gs.x.ravel()]
    if second:
        y0 += [skew_matrices(grp, gs.w).ravel(), gs.v.ravel()]
    sol = solve_ivp(written_out_model(scene), (0.0, max(times)), np.concatenate(y0),
                    method="DOP853", t_eval=sorted(times), rtol=3e-14, atol=1e-15)
    assert sol.success, sol.message
    states = []
    for k, t in enumerate(sol.t):
        parts = np.split(sol.y[:, k], np.cumsum([n * d * d, n * d, n * d * d])[:len(y0) - 1])
        extra = ((parts[3].reshape(n, d), grp.algebra_from_skew(parts[2].reshape(n, d, d)))
                 if second else ())
        states.append(State(float(t), (GroupState(parts[1].reshape(n, d),
                                                  grp.from_matrices(parts[0].reshape(n, d, d)),
                                                  *extra),)))
    return states
