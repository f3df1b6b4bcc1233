"""Synthetic scenes for timing: N congruent regular d-simplices, built through ``load_scene``."""


def timing_scene(n, dim, order=1, representation="auto", seed=0):
    """N regular d-simplices with centroids in [-5, 5]^d and uniformly random rotations.

    Second order (A-1): m = gamma = kappa = 1 with random centroid and angular
    velocities; first order (A-2): kappa = gamma = 1.  The values do not change
    the cost of a step, only the shapes of the arrays do.
    """
    from polymatch_ros.core.scenes.scene import load_scene
    model = {"order": order, "kappa": 1.0, "gamma": 1.0, "representation": representation}
    group = {"name": "simplices", "shape": {"simplex": dim}, "count": int(n),
             "centroids": {"box": [-5.0, 5.0]}, "rotations": "uniform"}
    if order == 2:
        model["mass"] = 1.0
        group["velocities"] = {"centroid": {"normal": 0.5}, "angular": {"normal": 0.5}}
    return load_scene({"name": f"timing_N{n}_d{dim}_order{order}", "dimension": dim, "seed": seed,
                       "model": model, "groups": [group]})


def representation_label(rotations):
    """'so3 (Cayley, SoA)', 'matrix (Cayley)', 'angle' for a core rotation group."""
    if rotations.name == "so3":
        return f"so3 ({'Cayley' if rotations.retraction == 'cayley' else 'exp/Rodrigues'}, SoA)"
    if rotations.name == "matrix":
        return "matrix (Cayley, N x d x d)"
    return rotations.name
