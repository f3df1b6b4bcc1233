"""The shipped parameter files (config/params/, one per node, the ``/**:`` wildcard) hold only
parameters their node declares, each of its declared type and in its range, none of what the
scene sets (a file's value would replace every scene's), and a node resolves and starts from
its file (``--params-file``, test/ros/test_param_file_runs.py)."""

import pathlib

import pytest
import yaml
from ros_harness import CONFIG

from polymatch_ros.ros.config.configs import (
    AgentConfig,
    MonitorConfig,
    RobotConfig,
    config_from,
    config_values,
)
from polymatch_ros.ros.config.params import AGENT, MONITOR, ROBOT, check, check_value
from polymatch_ros.ros.config.resolve import resolve_agent, resolve_monitor, resolve_robot

PARAMS = pathlib.Path(CONFIG) / "params"
FILES = {"agent.yaml": AGENT, "bridge_agent.yaml": AGENT, "monitor.yaml": MONITOR,
         "robot.yaml": ROBOT}
# rclpy's parameter types: a float parameter refuses an int, an int one a float
ROS_TYPES = {bool: (bool,), int: (int,), float: (float,), str: (str,)}
# what a node takes from its scene unless given: never in a file for every scene
FROM_THE_SCENE = {"integrator", "dt", "t_end", "kappa", "gamma", "mass"}
RESOLVE = {"agent.yaml": lambda c: resolve_agent(c).config,
           "bridge_agent.yaml": lambda c: resolve_agent(c).config,
           "monitor.yaml": lambda c: resolve_monitor(c)[0], "robot.yaml": resolve_robot}
CONFIG_OF = {"agent.yaml": AgentConfig, "bridge_agent.yaml": AgentConfig,
             "monitor.yaml": MonitorConfig, "robot.yaml": RobotConfig}


def _values(name):
    data = yaml.safe_load((PARAMS / name).read_text())
    assert list(data) == ["/**"] and list(data["/**"]) == ["ros__parameters"], data
    return data["/**"]["ros__parameters"]


def test_every_node_has_its_file_and_no_file_is_unchecked():
    assert sorted(p.name for p in PARAMS.glob("*.yaml")) == sorted(FILES)


@pytest.mark.parametrize("name", sorted(FILES))
def test_a_param_file_holds_declared_parameters_of_their_type_and_range(name):
    spec = {p.name: p for p in FILES[name]}
    values = _values(name)
    assert values and not {"scene", "agent"} & set(values)  # given per node
    assert not FROM_THE_SCENE & set(values), name
    for key, value in values.items():
        assert key in spec, f"{name}: {key} is not a parameter of this node"
        assert type(value) in ROS_TYPES[spec[key].kind], f"{name}: {key}: {value!r}"
        assert check_value(spec[key], value) == value


@pytest.mark.parametrize("name", sorted(FILES))
def test_a_param_file_resolves_on_a_shipped_scene_and_its_values_are_in_use(name):
    """What the node uses, from its file and the per-node scene and agent: every value of the
    file, and the scene's for the rest."""
    given = dict(_values(name), scene="congruent_triangles")
    used = config_values(RESOLVE[name](config_from(CONFIG_OF[name], check(FILES[name], given))))
    assert {k: used[k] for k in _values(name)} == _values(name)
    if name != "robot.yaml":
        assert used["t_end"] == 30.0  # config/congruent_triangles.yaml: time.t_end
