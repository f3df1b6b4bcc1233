"""What the exactness tests compare: the centralised run's vertices and the saved final poses."""

from dataclasses import replace

import numpy as np
from ros_harness import placed_vertices

from polymatch_ros.core.saved import load_saved
from polymatch_ros.core.stepping.simulate import simulate


def central_vertices(scene, integrator, t):
    sc = replace(scene, t_end=t)
    traj = simulate(sc, integrator, sc.integrator.dt, samples=[t], metrics=False)
    return placed_vertices(traj.scene.model, traj.final.groups, scene.origin)


def received_vertices(scene, path):
    """(t, per group its (vertex, agent, d) vertices) of the final poses a run saved, read with
    the one reader (``core.saved``)."""
    saved = load_saved(path)
    out = []
    for g, sg in zip(scene.model.groups, saved.groups):
        x, mats = sg.centroids[-1], sg.rotations[-1]
        out.append(x + np.einsum("nij,aj->nai", mats, g.reference).transpose(1, 0, 2))
    return saved.t, out
