"""`polymatch simulate --save` and `polymatch run --save` write one layout (``core.saved``):
the same keys, the same shapes but for the number of samples, read by the one reader.

Oracles: the scene file's own initial state (sample 0 of a simulation; the state handed to
the run's writer), SO(d) (R^T R = I, det R = 1), and the matching diameter of Ha & Park,
max over vertices a of max over pairs i, j of |x^i_a - x^j_a| (Section 2; similar groups at
their mean scale, F-1), by brute force over every pair."""

import itertools

import numpy as np
import pytest
from input_fuzz import run_main
from ros_harness import scene_path

from polymatch_ros.core.saved import GROUP_METRICS, load_saved
from polymatch_ros.core.scenes.scene import load_scene

SCENE = "similar_triangles"   # second order, with scales: every optional key is present


def _brute_force_diameter(centroids, rotations, reference, scales):
    """The matching diameter at one sample, over every pair of agents, vertex by vertex."""
    ref = reference if scales is None else reference * float(np.mean(scales))
    verts = [x + ref @ r.T for x, r in zip(centroids, rotations)]
    return max((float(np.linalg.norm(verts[i][a] - verts[j][a]))
                for i, j in itertools.combinations(range(len(verts)), 2)
                for a in range(len(ref))), default=0.0)


def _assert_consistent(path, scene, samples):
    """The file read back: shapes, rotations in SO(d), diameters by brute force."""
    saved = load_saved(path)
    d = scene.model.dim
    assert saved.times.shape == (samples,) and saved.diameter.shape == (samples,)
    assert np.array_equal(saved.origin, scene.origin)
    for g, sg in zip(scene.model.groups, saved.groups, strict=True):
        n = g.size
        assert sg.name == g.name and np.array_equal(sg.reference, g.reference)
        assert sg.centroids.shape == (samples, n, d)
        assert sg.rotations.shape == (samples, n, d, d)
        assert sg.agent_times.shape == (n,)
        r = sg.rotations
        assert np.allclose(r @ np.swapaxes(r, -1, -2), np.eye(d), atol=1e-12)
        assert np.allclose(np.linalg.det(r), 1.0, atol=1e-12)
        for k in (0, samples - 1):
            want = _brute_force_diameter(sg.centroids[k], r[k], g.reference, g.scales)
            assert sg.metrics["matching_diameter"][k] == pytest.approx(want, rel=1e-12)
    return saved


def _initial_centroids(scene):
    return [gs.x + scene.origin for gs in scene.initial.groups]


def test_simulate_and_run_save_one_layout_read_by_one_reader(tmp_path):
    from polymatch_ros.ros.supervisor.summary import save_final

    scene = load_scene(scene_path(SCENE))
    traj_file = tmp_path / "traj.npz"
    code, _, err = run_main(["simulate", SCENE, "-q", "--t-end", "1", "--save",
                             str(traj_file)], 120)
    assert code in (0, 3), err                     # 3: not converged by t = 1
    simulated = _assert_consistent(traj_file, scene, 3)    # samples every 0.5
    assert simulated.times[0] == 0.0 and simulated.t == pytest.approx(1.0)
    assert not simulated.partial
    for sg, x0 in zip(simulated.groups, _initial_centroids(scene)):
        assert np.allclose(sg.centroids[0], x0, rtol=0, atol=1e-15)
        assert np.all(sg.agent_times == simulated.t)

    run_file = tmp_path / "final.npz"
    agent_times = {a: 0.25 * (a % 3) for a in range(scene.model.n_agents)}
    save_final(str(run_file), scene, scene.initial, agent_times, partial=True)
    ran = _assert_consistent(run_file, scene, 1)
    assert ran.partial
    for g, sg, x0 in zip(scene.model.groups, ran.groups, _initial_centroids(scene)):
        assert np.array_equal(sg.centroids[0], x0)
        assert list(sg.agent_times) == [agent_times[a] for a in g.indices]

    per_sample = ("times", "diameter", "_centroids", "_rotations",
                  *("_" + m for m in GROUP_METRICS))
    with np.load(traj_file) as a, np.load(run_file) as b:
        assert sorted(a.files) == sorted(b.files)
        for key in a.files:        # a per-sample array's first axis counts the samples
            skip = 1 if key.endswith(per_sample) else 0
            assert a[key].shape[skip:] == b[key].shape[skip:], key
