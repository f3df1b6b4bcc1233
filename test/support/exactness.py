"""What the exactness tests compare: the centralised run's vertices and the saved final poses."""

from dataclasses import replace

import numpy as np
from ros_harness import placed_vertices

from polymatch_ros.core.stepping.simulate import simulate


def central_vertices(scene, integrator, t):
    sc = replace(scene, t_end=t)
    traj = simulate(sc, integrator, sc.integrator.dt, samples=[t], metrics=False)
    return placed_vertices(traj.scene.model, traj.final.groups, scene.origin)


def received_vertices(scene, path):
    data = np.load(path)
    out = []
    for gi, g in enumerate(scene.model.groups):
        x, mats = data[f"group{gi}_centroids"], data[f"group{gi}_rotations"]
        out.append(x + np.einsum("nij,aj->nai", mats, g.reference).transpose(1, 0, 2))
    return float(data["t"]), out
