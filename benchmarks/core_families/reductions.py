"""Model only what a scene requires: each reduction's cost against the full model it replaces.

For every reduction the scene applies on its own, the same run is made with the
full model and with the reduced one (same integrator, dt and initial state); the
table gives both wall times, their ratio and the largest difference in any vertex
at t_end — round-off for exact reductions, the stated error otherwise.
"""

NAME = "reductions"
HELP = ("cost of each model reduction (angles, SoA Cayley, no weights, exact centroids, ...) "
        "vs the full model")


def add_arguments(p):
    from ..options import add_number
    add_number(p, "--agents", 2, 1000, "agents per case")


def _scene(dim, n, t_end, **model):
    from polymatch_ros.core.scenes.scene import load_scene
    shape = {2: "triangle", 3: "tetrahedron"}[dim]
    spec = {"dimension": dim, "seed": 3,
            "model": {"order": 1, "kappa": 1.0, "gamma": 1.0, **model},
            "time": {"t_end": t_end, "samples": {"count": 2}},
            "groups": [{"name": "a", "shape": shape, "count": n, "rotations": {"within": 0.8},
                        "centroids": {"box": [-3, 3]}}]}
    if model.get("order") == 2:
        spec["groups"][0]["velocities"] = {"centroid": {"normal": 0.3}, "angular": {"normal": 0.3}}
    return load_scene(spec)


def _vertices(scene, state, rot):
    """Every vertex x^i_a = xbar_i + s_i O_i r_a of every group, absolute coordinates."""
    import numpy as np

    from polymatch_ros.core.metrics import vertices
    return np.concatenate([
        vertices(gs.x + scene.origin, rot.to_matrices(gs.rot), g.reference, g.scales)
        .reshape(-1, scene.dim) for g, gs in zip(scene.model.groups, state.groups)])


def _timed(scene, method, dt, repeats):
    import time

    from polymatch_ros.core.stepping.simulate import simulate
    best, traj = float("inf"), None
    for _ in range(repeats):
        t0 = time.perf_counter()
        traj = simulate(scene, method, dt, metrics=False, keep_states=False)
        best = min(best, time.perf_counter() - t0)
    return best, traj


def _copy_initial(dst, src):
    """Give ``dst`` exactly ``src``'s initial state (same agents, another model)."""
    import numpy as np
    for gd, gs in zip(dst.initial.groups, src.initial.groups):
        gd.x[:] = gs.x + src.origin - dst.origin
        if dst.model.rotations.name == src.model.rotations.name:
            gd.rot[...] = gs.rot
        else:
            gd.rot[...] = dst.model.rotations.from_matrices(
                src.model.rotations.to_matrices(gs.rot))
        if gd.v is not None and gs.v is not None:
            gd.v[:] = gs.v
        if gd.w is not None and gs.w is not None:
            gd.w[...] = dst.model.rotations.algebra_from_skew(
                src.model.rotations.algebra_to_skew(gs.w))
    return np.asarray(0)


def _compare(case, repeats, log):
    """Run a case's full and reduced models alike; its table row."""
    import numpy as np

    name, full, full_method, reduced, reduced_method, expectation, note = case
    log(note or name)
    t_full, a = _timed(full, full_method, 0.05, repeats)
    t_red, b = _timed(reduced, reduced_method, 0.05, repeats)
    diff = float(np.max(np.abs(_vertices(full, a.final, a.scene.model.rotations)
                               - _vertices(reduced, b.final, b.scene.model.rotations))))
    return [name, f"{t_full * 1e3:.1f}", f"{t_red * 1e3:.1f}", f"{t_full / t_red:.1f}x",
            f"{diff:.1e}", expectation]


def _two_groups(m, t_end):
    """m triangles and m tetrahedra without the inter-group potential (kappa_2 = 0)."""
    from polymatch_ros.core.scenes.scene import load_scene

    return load_scene({"dimension": 3, "seed": 5, "model": {"order": 1, "kappa_2": 0.0, "L": 3.0},
                       "time": {"t_end": t_end, "samples": {"count": 2}},
                       "groups": [{"name": "tri", "shape": "triangle", "count": m,
                                   "centroids": {"box": [-2, 2]}},
                                  {"name": "tet", "shape": "tetrahedron", "count": m,
                                   "centroids": {"box": [-2, 2]}}]})


def _unweighted(n, t_end, like):
    """``like``'s agents in a scene that states no scale weights."""
    from polymatch_ros.core.scenes.scene import load_scene

    sim = load_scene({"dimension": 3, "seed": 3, "time": {"t_end": t_end, "samples": {"count": 2}},
                      "groups": [{"name": "a", "shape": "tetrahedron", "count": n,
                                  "rotations": {"within": 0.8}, "centroids": {"box": [-3, 3]},
                                  "scales": [1.0] * n}]})
    _copy_initial(sim, like)
    return sim


def _at_rest_second_order(n, t_end, like):
    """``like``'s agents under (A-1) with m = 1e-3, starting at rest."""
    second = _scene(3, n, t_end, order=2, mass=1e-3)
    _copy_initial(second, like)
    for g in second.initial.groups:
        g.v[:] = 0.0
        g.w[...] = 0.0
    return second


def _cases(n, t_end):
    """(name, full, its method, reduced, its method, expected difference, log line or None)
    of every reduction, built one at a time as they are run."""
    from dataclasses import replace

    from polymatch_ros.core.stepping.simulate import with_representation

    s2 = _scene(2, n, t_end)
    yield ("2-D: angles (Kuramoto) vs 2x2 matrices", with_representation(s2, "matrix"), "rkmk4",
           s2, "rkmk4", "round-off", None)
    s3 = _scene(3, n, t_end)
    yield ("3-D: SoA Cayley vs (N,3,3) matrices", with_representation(s3, "matrix"), "rkmk4",
           s3, "rkmk4", "round-off", None)
    yield ("congruent: no scale weights vs F-1 weights s_k/s_i = 1", _unweighted(n, t_end, s3),
           "rkmk4", s3, "rkmk4", "round-off", None)
    s2nd = _scene(3, n, t_end, order=2, mass=0.5)
    yield ("centroids: exact flow (Prop. 2.1) vs integrated by rkmk4",
           replace(s2nd, model=replace(s2nd.model, centroids="integrated")), "rkmk4",
           s2nd, "rkmk4", "rkmk4's O(dt^4) centroid error", None)
    m = max(4, n // 5)
    reduced = _two_groups(m, t_end)
    # potential on, force ~ 0
    yield (f"kappa_2 = 0: no inter-group potential ({m} + {m} agents)",
           replace(reduced, model=replace(reduced.model, kappa_2=1e-300)), "rkmk4",
           reduced, "rkmk4", "rkmk4's centroid error (with a potential, centroids are integrated)",
           None)
    first = _scene(3, n, t_end)
    yield ("first order (A-2) vs second order m = 1e-3 (etd2 / rkmk4)",
           _at_rest_second_order(n, t_end, first), "etd2", first, "rkmk4",
           "O(m/gamma) modelling error", "first order (A-2) vs (A-1) with m = 1e-3")


def run(args, log):
    from ..report import Report

    n = 40 if args.quick else args.agents
    t_end = 0.2 if args.quick else 2.0
    repeats = 1 if args.quick else (args.repeats or 3)
    report = Report(NAME, "Model only what a scene requires (`python -m benchmarks reductions`)")
    rows = [_compare(case, repeats, log) for case in _cases(n, t_end)]
    report.table(["reduction", "full model ms", "reduced ms", "full / reduced",
                  "max vertex difference at t_end", "expected difference"], rows,
                 caption=f"N = {n} agents (first-order model unless stated), t_end = {t_end:g}, "
                         f"dt = 0.05, best of {repeats}")
    report.text("- Every reduction is applied by the scene loader on its own; "
                "`polymatch explain SCENE` says which.",
                "- The full models are what the paper writes: d x d matrices, weights s_k/s_i, "
                "the F-2 potential, centroids as ODEs, velocities in (A-1).")
    return report
