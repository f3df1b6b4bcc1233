"""A node starts from its shipped parameter file (config/params/, ``--params-file``)."""

import pathlib

from ros_harness import CONFIG, PY, needs_ros

PARAMS = pathlib.Path(CONFIG) / "params"


@needs_ros
def test_an_agent_runs_from_its_param_file(ros, tmp_path):
    """One lockstep agent alone (a one-agent scene) from config/params/agent.yaml."""
    scene = tmp_path / "solo.yaml"
    scene.write_text(
        "name: solo\ndimension: 3\nseed: 1\nmodel: {order: 1}\n"
        "integrator: {method: rkmk4, dt: 0.1}\ntime: {t_end: 1.0}\n"
        "groups:\n  - {name: one, shape: tetrahedron, count: 1}\n"
    )
    agent = ros.start([PY, "-m", "polymatch_ros.cli", "agent", "--ros-args", "--params-file",
                       str(PARAMS / "agent.yaml"), "-p", f"scene:={scene}", "-p", "agent:=0"],
                      timeout=60)
    assert ros.wait(agent, 70) == 0, ros.output(agent)
    assert "agent 0: finished at t = 1 after 10 steps" in ros.output(agent), ros.output(agent)
