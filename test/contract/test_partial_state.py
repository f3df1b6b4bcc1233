"""The partial state a run ended early saves: each agent's last checkpointed state, in the
scene's representation of rotations."""

import numpy as np
from ros_harness import scene_path

SCENE = "congruent_triangles"


def test_a_partial_state_from_a_projection_methods_checkpoint_is_in_the_scenes_rotations():
    """A 2-D projection integrator's agents checkpoint matrices
    (``core.stepping.simulate.prepare``)
    where the scene keeps angles: the partial state holds each agent's checkpointed rotation
    in the scene's representation (an agent without a checkpoint: its initial one)."""
    from polymatch_ros.core.model import GroupState, State
    from polymatch_ros.core.scenes.scene import load_scene
    from polymatch_ros.core.stepping.simulate import choose_numerics, prepare
    from polymatch_ros.ros.supervisor.partial import last_state
    from polymatch_ros.ros.wire.checkpoint import Checkpoint

    scene = load_scene(scene_path(SCENE))
    numerics = choose_numerics(scene, "rk4_proj", 0.05, distributed=True)
    computed = prepare(scene, numerics, distributed=True)
    grp = computed.model.rotations
    assert (scene.model.rotations.name, grp.name) == ("angle", "matrix")
    angles = np.array([0.25, -2.75])
    local = State(1.5, (GroupState(np.array([[1.0, 2.0], [3.0, 4.0]]),
                                   grp.from_matrices(scene.model.rotations.to_matrices(angles))),))
    state, times = last_state(scene, {}, [((2, 3), Checkpoint(30, 1.5, local, 7))], grp)
    assert times[2] == times[3] == 1.5 and times[0] == 0.0
    assert np.allclose(state.groups[0].rot[2:4], angles, rtol=0, atol=1e-15)
    assert state.groups[0].rot[0] == scene.initial.groups[0].rot[0]
