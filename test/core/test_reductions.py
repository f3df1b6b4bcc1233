"""Model only what a scene requires: each reduction gives the same trajectory as the full model.

The scene picks the smallest exact model: angles in 2-D and the SoA Cayley form in 3-D
(tested against the full matrix model in test_core_integrators.py), no scale weights for
congruent groups, no inter-group potential for one group (or kappa_2 = 0), centroids in
closed form where they decouple, no velocities for the first-order model.  Each test
runs reduced and full side by side; `polymatch bench reductions` reports the cost ratios.
"""

import numpy as np

from polymatch_ros.core.scenes.scene import load_scene
from polymatch_ros.core.stepping.simulate import simulate


def _scene(**over):
    base = {"dimension": 3, "seed": 4, "model": {"order": 1, "kappa": 1.0, "gamma": 1.0},
            "integrator": {"method": "rkmk4", "dt": 0.05},
            "time": {"t_end": 3.0, "samples": {"count": 2}},
            "groups": [{"name": "a", "shape": "tetrahedron", "count": 6,
                        "rotations": {"within": 0.6}, "centroids": {"box": [-3, 3]}}]}
    for key, value in over.items():
        node = base
        parts = key.split(".")
        for p in parts[:-1]:
            node = node[p] if not p.isdigit() else node[int(p)]
        node[parts[-1] if not parts[-1].isdigit() else int(parts[-1])] = value
    return load_scene(base)


def _final(scene, method="rkmk4", dt=0.05):
    traj = simulate(scene, method, dt, samples=[scene.t_end], metrics=False, keep_states=False)
    rot = traj.scene.model.rotations
    return traj.final, rot


def _vertices(scene, state, rot):
    out = []
    for g, gs in zip(scene.model.groups, state.groups):
        mats = rot.to_matrices(gs.rot)
        s = np.ones(len(mats)) if g.scales is None else g.scales
        out.append(gs.x[:, None, :]
                   + s[:, None, None] * np.einsum("nij,aj->nai", mats, g.reference))
    return np.concatenate([v.reshape(-1, scene.dim) for v in out])


def test_reduction_congruent_drops_scale_weights_F_1():
    """A similar ensemble with all s_i = 1 is the congruent model (A-2): weights s_k/s_i = 1."""
    full = _scene(**{"groups.0.scales": [1.0] * 6})
    reduced = _scene()
    assert full.model.groups[0].scales is not None and reduced.model.groups[0].scales is None
    a, ra = _final(full)
    b, rb = _final(reduced)
    assert np.max(np.abs(_vertices(full, a, ra) - _vertices(reduced, b, rb))) <= 1e-13


def test_reduction_exact_centroid_flow_prop_2_1_matches_integrated_centroids():
    """Closed-form centroids vs centroids carried by rkmk4's stages: equal to rkmk4's O(dt^4)
    error."""
    second = {"model.mass": 0.5, "groups.0.velocities": {"centroid": {"normal": 0.5}}}
    for order, extra in ((1, {}), (2, second)):
        model = {"order": order, "kappa": 1.0, "gamma": 1.0,
            **({"mass": 0.5} if order == 2 else {})}
        exact = _scene(**{"model": dict(model)},
                       **{k: v for k, v in extra.items() if k != "model.mass"})
        full = _scene(**{"model": dict(model, centroids="integrated")},
                      **{k: v for k, v in extra.items() if k != "model.mass"})
        assert exact.model.centroids_exact and not full.model.centroids_exact
        errs = []
        for dt in (0.1, 0.05):
            a, _ = _final(exact, dt=dt)
            b, _ = _final(full, dt=dt)
            errs.append(np.max(np.abs(a.groups[0].x - b.groups[0].x)))
            rot_diff = np.asarray(a.groups[0].rot) - np.asarray(b.groups[0].rot)
            assert np.max(np.abs(rot_diff)) <= 1e-13
        # the integrated copy converges at order 4
        assert errs[0] < 1e-4 and errs[0] / errs[1] > 2 ** 3.5


def test_reduction_no_inter_group_potential_when_kappa_2_is_0_F_2():
    """Two groups with kappa_2 = 0 are two independent single-group problems."""
    two = {"dimension": 3, "seed": 5, "model": {"order": 2, "mass": 0.3, "kappa_2": 0.0, "L": 3.0},
           "time": {"t_end": 2.0, "samples": [2.0]},
           "groups": [{"name": "tri", "shape": "triangle", "count": 4,
                       "centroids": {"box": [-2, 2]}},
                      {"name": "tet", "shape": "tetrahedron", "count": 5,
                       "centroids": {"box": [-2, 2]}}]}
    both = load_scene(two)
    assert not both.model.inter_group
    a, ra = _final(both)
    for gi, g in enumerate(two["groups"]):
        alone = load_scene(dict(two, groups=[g]))
        # the same initial state as inside the two-group scene (seeded draws differ): copy it
        alone.initial.groups[0].x[:] = both.initial.groups[gi].x + both.origin - alone.origin
        alone.initial.groups[0].rot[...] = both.initial.groups[gi].rot
        alone.initial.groups[0].v[:] = both.initial.groups[gi].v
        alone.initial.groups[0].w[...] = both.initial.groups[gi].w
        b, rb = _final(alone)
        got = a.groups[gi].x + both.origin
        want = b.groups[0].x + alone.origin
        assert np.max(np.abs(got - want)) <= 1e-12
        rot_diff = ra.to_matrices(a.groups[gi].rot) - rb.to_matrices(b.groups[0].rot)
        assert np.max(np.abs(rot_diff)) <= 1e-13


def test_reduction_first_order_model_is_the_m_to_0_limit_of_A_1():
    """(A-2) carries no velocities; (A-1) with small m (etd2) differs by O(m/gamma)."""
    first = _scene(**{"time.t_end": 2.0})
    # dt = 0.01: the differences agree with those at dt = 0.002 to < 3e-4 relative (4.0e-3,
    # 4.0e-4: the integrators' errors are far below the model's; etd2 damps exactly)
    a, ra = _final(first, "rkmk4", 0.01)
    diffs = []
    for m in (1e-2, 1e-3):
        second = _scene(**{"time.t_end": 2.0, "model": {"order": 2,
                        "mass": m, "kappa": 1.0, "gamma": 1.0}})
        assert second.initial.groups[0].w is not None and first.initial.groups[0].w is None
        b, rb = _final(second, "etd2", 0.01)
        diffs.append(np.max(np.abs(_vertices(first, a, ra) - _vertices(second, b, rb))))
    assert diffs[0] < 5e-2
    # linear in m: a modelling error, not noise
    assert 5 < diffs[0] / diffs[1] < 20
