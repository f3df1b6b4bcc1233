"""ROS parameters: bad ones are one line and exit code 2 (every parameter of the agent and the
monitor, with a wrong type and out of its range, checked in-process: ``params.check`` runs
before the nodes create any topic; the real processes are covered in test_robustness.py), and
the declared ones hold what the node uses: the scene's gains, integrator, step and end time
unless given (a running node's, read back through the rcl_interfaces services as `ros2 param
get` does: test/ros/test_params_over_ros.py)."""

import os
import re
from types import SimpleNamespace

import pytest
from param_tables import LOCKSTEP_TABLE, REALTIME_TABLE
from ros_harness import CONFIG, needs_ros, scene_path

from polymatch_ros.core.errors import ParameterError, PolymatchError
from polymatch_ros.core.scenes.scene import load_scene
from polymatch_ros.ros.config.configs import (
    AgentConfig,
    MonitorConfig,
    RobotConfig,
    config_from,
    config_values,
)
from polymatch_ros.ros.config.params import AGENT, MONITOR, ROBOT, check, check_gains
from polymatch_ros.ros.config.resolve import resolve_agent, resolve_monitor, resolve_robot

AGENT_NAMES = [
    "scene", "agent", "agents", "agents_per_process", "agent_nodes", "mode", "autostart",
    "integrator", "dt", "t_end", "rate", "kappa", "gamma", "mass", "time_scale", "start",
    "start_time", "peer_timeout", "delay",
    "clock_offset_warn", "hold_final", "round_timeout", "stall_timeout", "peers_restart",
    "checkpoint", "discovery_timeout",
    "pose_subscribers", "exchange_subscribers", "exchange_rate", "frame_id", "max_linear_speed",
    "max_angular_speed", "max_linear_accel", "max_angular_accel", "pose_timeout", "pose_type",
    "cmd_type", "command_frame", "drive", "axle_offset", "safety_radius", "safety_alpha",
    "safety_latency", "safety_stale", "run_id",
]
MONITOR_NAMES = ["scene", "mode", "rate", "report_rate", "peer_timeout", "frame_id", "markers",
                 "t_end", "run_id", "agents_per_process", "report_readers"]

STRING, BOOLEAN, INTEGER, NUMBER = ("expected a string", "expected a boolean",
                                    "expected an integer", "expected a number")
# (spec, parameter, a value of the wrong type, the words of the error)
TYPE_CASES = [
    ("agent", "scene", 1.5, STRING), ("agent", "agent", 2.5, INTEGER),
    ("agent", "agent", True, INTEGER), ("agent", "agents", 1.5, "expected a list of integers"),
    ("agent", "agents", [1, 2.5], "expected a list of integers"),
    ("agent", "agents_per_process", 2.5, INTEGER), ("agent", "mode", 1.5, STRING),
    ("agent", "agent_nodes", 1, STRING),
    ("agent", "autostart", 1.5, BOOLEAN), ("agent", "autostart", "true", BOOLEAN),
    ("agent", "integrator", 1.5, STRING), ("agent", "dt", "abc", NUMBER),
    ("agent", "dt", True, NUMBER), ("agent", "dt", float("nan"), NUMBER),
    ("agent", "t_end", "abc", NUMBER), ("agent", "t_end", float("inf"), NUMBER),
    ("agent", "rate", "abc", NUMBER), ("agent", "kappa", "abc", NUMBER),
    ("agent", "gamma", "abc", NUMBER), ("agent", "mass", "abc", NUMBER),
    ("agent", "time_scale", "abc", NUMBER), ("agent", "start", 1.5, STRING),
    ("agent", "start_time", "abc", NUMBER), ("agent", "peer_timeout", "abc", NUMBER),
    ("agent", "delay", "abc", NUMBER), ("agent", "clock_offset_warn", "abc", NUMBER),
    ("agent", "hold_final", "abc", NUMBER), ("agent", "round_timeout", "abc", NUMBER),
    ("agent", "stall_timeout", "abc", NUMBER), ("agent", "peers_restart", 1, BOOLEAN),
    ("agent", "checkpoint", 1.5, STRING), ("agent", "discovery_timeout", "abc", NUMBER),
    ("agent", "pose_subscribers", 2.5, INTEGER), ("agent", "frame_id", 1.5, STRING),
    ("agent", "exchange_subscribers", 2.5, INTEGER), ("monitor", "run_id", 2.5, INTEGER),
    ("agent", "exchange_rate", "abc", NUMBER),
    ("monitor", "agents_per_process", 1.5, INTEGER),
    ("agent", "max_linear_speed", "abc", NUMBER), ("agent", "max_angular_speed", "abc", NUMBER),
    ("agent", "max_linear_accel", "abc", NUMBER), ("agent", "max_angular_accel", "abc", NUMBER),
    ("agent", "pose_timeout", "abc", NUMBER), ("agent", "pose_type", 1.5, STRING),
    ("agent", "cmd_type", 1.5, STRING), ("agent", "command_frame", 1.5, STRING),
    ("agent", "run_id", 2.5, INTEGER), ("agent", "drive", 1.5, STRING),
    ("agent", "axle_offset", "abc", NUMBER), ("agent", "safety_radius", "abc", NUMBER),
    ("agent", "safety_alpha", "abc", NUMBER), ("agent", "safety_latency", "abc", NUMBER),
    ("agent", "safety_stale", "abc", NUMBER),
    ("monitor", "scene", 1.5, STRING), ("monitor", "mode", 1.5, STRING),
    ("monitor", "rate", "abc", NUMBER), ("monitor", "report_rate", "abc", NUMBER),
    ("monitor", "peer_timeout", "abc", NUMBER), ("monitor", "frame_id", 1.5, STRING),
    ("monitor", "markers", 1.5, BOOLEAN), ("monitor", "t_end", "abc", NUMBER),
    ("monitor", "report_readers", 2.5, INTEGER),
]
# (spec, parameter, lowest accepted, highest accepted, just below, just above, range text)
RANGE_CASES = [
    ("agent", "agent", 0, 1_000_000, -1, 1_000_001, "[0, 1e+06]"),
    ("agent", "agents_per_process", 1, 1_000_000, 0, 1_000_001, "[1, 1e+06]"),
    ("monitor", "agents_per_process", 1, 1_000_000, 0, 1_000_001, "[1, 1e+06]"),
    ("agent", "dt", 1e-12, 1e6, 0.0, 1.000001e6, "[1e-12, 1e+06]"),
    ("agent", "t_end", 1e-12, 1e12, 0.0, 1.000001e12, "[1e-12, 1e+12]"),
    ("agent", "rate", 0.01, 1e5, 0.0099, 100000.1, "[0.01, 100000]"),
    ("agent", "kappa", 0.0, 1e6, -1e-9, 1.000001e6, "[0, 1e+06]"),
    ("agent", "gamma", 0.0, 1e6, -1e-9, 1.000001e6, "[0, 1e+06]"),
    ("agent", "mass", 1e-12, 1e6, 0.0, 1.000001e6, "[1e-12, 1e+06]"),
    ("agent", "time_scale", 1e-6, 1e6, 9.9e-7, 1.000001e6, "[1e-06, 1e+06]"),
    ("agent", "start_time", 0.0, 1e12, -1e-9, 1.000001e12, "[0, 1e+12]"),
    ("agent", "peer_timeout", 0.001, 1e6, 0.00099, 1.000001e6, "[0.001, 1e+06]"),
    ("agent", "delay", 0.0, 1e6, -1e-9, 1.000001e6, "[0, 1e+06]"),
    ("agent", "clock_offset_warn", 0.0, 1e6, -1e-9, 1.000001e6, "[0, 1e+06]"),
    ("agent", "hold_final", 0.0, 1e6, -1e-9, 1.000001e6, "[0, 1e+06]"),
    ("agent", "round_timeout", 0.001, 1e6, 0.00099, 1.000001e6, "[0.001, 1e+06]"),
    ("agent", "stall_timeout", 0.001, 1e6, 0.00099, 1.000001e6, "[0.001, 1e+06]"),
    ("agent", "discovery_timeout", 0.0, 1e6, -1e-9, 1.000001e6, "[0, 1e+06]"),
    ("agent", "pose_subscribers", 0, 100_000, -1, 100_001, "[0, 100000]"),
    ("agent", "exchange_subscribers", 0, 100_000, -1, 100_001, "[0, 100000]"),
    ("agent", "exchange_rate", 0.0, 1e6, -1e-9, 1.000001e6, "[0, 1e+06]"),
    ("monitor", "run_id", 0, 2**31 - 1, -1, 2**31, "[0, 2.14748e+09]"),
    ("agent", "max_linear_speed", 0.0, 1e6, -1e-9, 1.000001e6, "[0, 1e+06]"),
    ("agent", "max_angular_speed", 0.0, 1e6, -1e-9, 1.000001e6, "[0, 1e+06]"),
    ("agent", "max_linear_accel", 0.0, 1e6, -1e-9, 1.000001e6, "[0, 1e+06]"),
    ("agent", "max_angular_accel", 0.0, 1e6, -1e-9, 1.000001e6, "[0, 1e+06]"),
    ("agent", "pose_timeout", 0.001, 1e6, 0.00099, 1.000001e6, "[0.001, 1e+06]"),
    ("agent", "run_id", 0, 2**31 - 1, -1, 2**31, "[0, 2.14748e+09]"),
    ("agent", "axle_offset", 1e-6, 1e3, 9.9e-7, 1000.001, "[1e-06, 1000]"),
    ("agent", "safety_radius", 0.0, 1e6, -1e-9, 1.000001e6, "[0, 1e+06]"),
    ("agent", "safety_alpha", 0.0, 1e6, -1e-9, 1.000001e6, "[0, 1e+06]"),
    ("agent", "safety_latency", 0.0, 10.0, -1e-9, 10.000001, "[0, 10]"),
    ("agent", "safety_stale", 0.0, 1e6, -1e-9, 1.000001e6, "[0, 1e+06]"),
    ("monitor", "rate", 0.01, 1e4, 0.0099, 10000.01, "[0.01, 10000]"),
    ("monitor", "report_rate", 0.01, 1e4, 0.0099, 10000.01, "[0.01, 10000]"),
    ("monitor", "peer_timeout", 0.001, 1e6, 0.00099, 1.000001e6, "[0.001, 1e+06]"),
    ("monitor", "t_end", 1e-12, 1e12, 0.0, 1.000001e12, "[1e-12, 1e+12]"),
    ("monitor", "report_readers", 0, 1000, -1, 1001, "[0, 1000]"),
]
# (spec, parameter, the allowed values)
CHOICE_CASES = [
    ("agent", "mode", ("lockstep", "realtime", "bridge")),
    ("agent", "agent_nodes", ("full", "lean", "none")),
    ("agent", "start", ("now", "control", "at")),
    ("agent", "pose_type", ("pose", "odometry")),
    ("agent", "cmd_type", ("twist_stamped", "twist")),
    ("agent", "command_frame", ("world", "body")),
    ("agent", "drive", ("holonomic", "unicycle")),
    ("monitor", "mode", ("lockstep", "realtime")),
]
SPECS = {"agent": AGENT, "monitor": MONITOR}


def test_the_tables_declare_exactly_the_pinned_parameters():
    assert [p.name for p in AGENT] == AGENT_NAMES
    assert [p.name for p in MONITOR] == MONITOR_NAMES
    for spec_name, names in (("agent", AGENT_NAMES), ("monitor", MONITOR_NAMES)):
        spec = SPECS[spec_name]
        assert {c[1] for c in TYPE_CASES if c[0] == spec_name} == set(names)
        assert {c[1] for c in RANGE_CASES if c[0] == spec_name} == \
            {p.name for p in spec if p.bounds is not None}
        assert {c[1] for c in CHOICE_CASES if c[0] == spec_name} == \
            {p.name for p in spec if p.choices is not None}


def _refused(spec_name, name, value):
    values = {"scene": "congruent_triangles", name: value}
    with pytest.raises(ParameterError) as info:
        check(SPECS[spec_name], values)
    text = str(info.value)
    assert info.value.exit_code == 2 and len(text.splitlines()) == 1, text
    assert text.startswith(f"parameter {name!r}: "), text
    return text


@pytest.mark.parametrize("spec_name,name,value,words", TYPE_CASES)
def test_wrong_type_is_one_line_parameter_error(spec_name, name, value, words):
    assert words in _refused(spec_name, name, value)


@pytest.mark.parametrize("spec_name,name,lowest,highest,below,above,bounds", RANGE_CASES)
def test_range_is_checked_at_and_just_past_each_bound(spec_name, name, lowest, highest, below,
                                                      above, bounds):
    spec = SPECS[spec_name]
    for value in (lowest, highest):
        assert check(spec, {"scene": "x", name: value})[name] == value
    for value in (below, above):
        assert f"{value:g} is out of range {bounds}" in _refused(spec_name, name, value)


@pytest.mark.parametrize("spec_name,name,allowed", CHOICE_CASES)
def test_choices_are_the_pinned_values(spec_name, name, allowed):
    for value in allowed:
        assert check(SPECS[spec_name], {"scene": "x", name: value})[name] == value
    text = _refused(spec_name, name, "fast")
    assert f"expected {' or '.join(allowed)}, got 'fast'" in text


def test_negative_agent_indices_are_refused():
    assert "indices must be >= 0, got [1, -2]" in _refused("agent", "agents", [1, -2])


def test_good_parameters_pass_and_integers_are_numbers():
    values = check(AGENT, {"scene": "x", "t_end": 2, "agents": [1, 2], "mode": "realtime"})
    assert (
        values["t_end"] == 2.0
        and isinstance(values["t_end"], float)
        and values["agents"] == [1, 2]
    )
    assert check(MONITOR, {"scene": "x"})["markers"] is True


def test_missing_scene_is_an_error():
    with pytest.raises(ParameterError, match="'scene' is required"):
        check(MONITOR, {})


def test_polymatch_set_waits_for_every_agent_the_run_records_name():
    """`polymatch set` calls once the records cover the ensemble and their nodes are in the
    graph: one of two nodes in the graph (discovery on a loaded machine) is not enough."""
    from polymatch_ros.ros.supervisor.param_set import _not_found
    from polymatch_ros.ros.wire import RunRecord

    def record(agents, name):
        return RunRecord(role="agent", mode="realtime", t=0.0, agents=agents, n_agents=8,
                         node=f"/polymatch/{name}")

    records = {"agents_0_3": record((0, 1, 2, 3), "agents_0_3"),
               "agents_4_7": record((4, 5, 6, 7), "agents_4_7")}
    assert _not_found(records, ["agents_0_3"]) == [4, 5, 6, 7]
    assert _not_found(records, ["agents_0_3", "agents_4_7"]) == []
    assert _not_found({"agents_0_3": records["agents_0_3"]}, ["agents_0_3"]) == [4, 5, 6, 7]
    # the record survives its JSON line (the status topic carries it so)
    again = RunRecord.from_json(records["agents_4_7"].to_json())
    assert (again.n_agents, again.node) == (8, "/polymatch/agents_4_7")


# -- the declared values are the values in use -------------------------------------------------

# what each shipped scene file sets (read off the file: model, integrator, time); stiff_mass asks
# for `auto`, and its comment names the method that picks: etd2
SCENE_FILES = {
    "congruent_triangles": dict(kappa=1.0, gamma=1.0, mass=None, integrator="rkmk4", dt=0.05,
                                t_end=30.0),
    "congruent_triangles_second_order": dict(kappa=1.0, gamma=1.0, mass=0.5, integrator="rkmk4",
                                             dt=0.05, t_end=50.0),
    "similar_triangles": dict(kappa=1.0, gamma=1.0, mass=0.2, integrator="rkmk4", dt=0.05,
                              t_end=40.0),
    "extremes/stiff_mass": dict(kappa=1.5, gamma=2.0, mass=1e-8, integrator="etd2", dt=0.02,
                                t_end=30.0),
}


def _agent_config(**given):
    return resolve_agent(config_from(AgentConfig, check(AGENT, given))).config


def _agent_values(**given):
    return config_values(_agent_config(**given))


def _declared(values):
    """What a node declares of its resolved values: None is not declared."""
    return {k: v for k, v in values.items() if v is not None}


@pytest.mark.parametrize("scene", sorted(SCENE_FILES))
@pytest.mark.parametrize("mode", ["lockstep", "realtime", "bridge"])
def test_agent_parameters_hold_the_scene_values_in_every_mode(scene, mode):
    values = _agent_values(scene=scene, mode=mode)
    want = dict(SCENE_FILES[scene], dt=SCENE_FILES[scene]["dt"] if mode == "lockstep" else None)
    assert {k: values[k] for k in want} == want
    assert values["scene"] == os.path.join(CONFIG, scene + ".yaml")


def test_every_parameter_of_a_lockstep_agent_is_the_value_it_uses():
    values = _agent_values(scene="congruent_triangles", discovery_timeout=120.0)
    assert _declared(values) == LOCKSTEP_TABLE


def test_every_parameter_of_a_realtime_agent_is_the_value_it_uses_or_was_given():
    values = _agent_values(scene="congruent_triangles_second_order", mode="realtime", gamma=2.0,
                           rate=5.0)
    assert _declared(values) == REALTIME_TABLE


# (scene, mode, given, the values then in use)
OVERRIDES = [
    ("congruent_triangles_second_order", "realtime",
     dict(kappa=2.5, gamma=0.5, mass=0.25, integrator="lie_heun", t_end=7.0, rate=20.0),
     dict(kappa=2.5, gamma=0.5, mass=0.25, integrator="lie_heun", t_end=7.0, rate=20.0,
          dt=None)),
    ("congruent_triangles_second_order", "realtime", dict(gamma=0.0),  # undamped
     dict(kappa=1.0, gamma=0.0, mass=0.5)),
    ("congruent_triangles", "lockstep", dict(integrator="lie_heun", dt=0.01, t_end=2.0),
     dict(kappa=1.0, gamma=1.0, mass=None, integrator="lie_heun", dt=0.01, t_end=2.0)),
    ("congruent_triangles", "lockstep", dict(t_end=2.0, dt=5.0), dict(dt=2.0)),  # one step
    ("congruent_triangles", "bridge", dict(kappa=0.5, rate=10.0),
     dict(kappa=0.5, gamma=1.0, rate=10.0, dt=None)),
    ("congruent_triangles", "realtime", dict(), dict(start="now", start_time=None)),
    ("congruent_triangles", "realtime", dict(start_time=1.7e9),
     dict(start="at", start_time=1.7e9)),
    ("congruent_triangles", "bridge", dict(start="control"),
     dict(start="control", start_time=None)),
    ("congruent_triangles", "lockstep", dict(agents=[4, 5]), dict(agent=4, agents=[4, 5])),
    ("congruent_triangles", "lockstep", dict(agent=3), dict(agent=3, agents=[3])),
    ("congruent_triangles", "lockstep", dict(agent=4, agents=[4, 5]),
     dict(agent=4, agents=[4, 5])),
]


@pytest.mark.filterwarnings("ignore:dt = 5 is larger than t_end")
@pytest.mark.parametrize("scene,mode,given,want", OVERRIDES)
def test_a_given_parameter_is_the_value_in_use(scene, mode, given, want):
    values = _agent_values(scene=scene, mode=mode, **given)
    assert {k: values[k] for k in want} == want


# (scene, given, the words of the one-line error)
SECOND = "congruent_triangles_second_order"
REFUSED = [
    ("congruent_triangles", dict(kappa=2.0),
     "parameter 'kappa': realtime and bridge only (lockstep runs the scene's model"),
    ("congruent_triangles", dict(start="now"), "parameter 'start': realtime and bridge only"),
    ("congruent_triangles", dict(mode="realtime", dt=0.01), "parameter 'dt': lockstep only"),
    ("congruent_triangles", dict(mode="realtime", mass=1.0),
     "parameter 'mass': the scene's model is first order (A-2)"),
    ("congruent_triangles", dict(mode="realtime", gamma=0.0),
     "parameter 'gamma': the first-order model (A-2) needs gamma > 0, got 0"),
    (SECOND, dict(mode="bridge", gamma=0.0, pose_type="odometry"),
     "parameter 'gamma': mode bridge: a second-order scene needs gamma > 0"),
    ("congruent_triangles", dict(mode="realtime", start="at"),
     "parameter 'start': at needs 'start_time'"),
    ("congruent_triangles", dict(mode="realtime", start="control", start_time=5.0),
     "parameter 'start_time': a time of t = 0 with start control"),
    ("congruent_triangles", dict(agent=3, agents=[4, 5]),
     "parameters 'agent', 'agents': agent 3 is not the first of agents [4, 5]"),
    ("congruent_triangles", dict(t_end=0.0),
     "parameter 't_end': 0 is out of range [1e-12, 1e+12]"),
    ("congruent_triangles", dict(dt=0.0), "parameter 'dt': 0 is out of range [1e-12, 1e+06]"),
    (SECOND, dict(mode="realtime", mass=0.0),
     "parameter 'mass': 0 is out of range [1e-12, 1e+06]"),
]


@pytest.mark.parametrize("scene,given,words", REFUSED)
def test_a_parameter_the_mode_or_model_cannot_take_is_one_line(scene, given, words):
    with pytest.raises(PolymatchError) as info:
        _agent_values(scene=scene, **given)
    text = str(info.value)
    assert info.value.exit_code == 2 and len(text.splitlines()) == 1, text
    assert words in text, text


def test_monitor_and_robot_parameters_are_the_values_they_use():
    def monitor(**given):
        return resolve_monitor(config_from(MonitorConfig, check(MONITOR, given)))[0]

    def robot(**given):
        return resolve_robot(config_from(RobotConfig, check(ROBOT, given)))

    got = monitor(scene="congruent_triangles")
    assert (got.scene, got.t_end) == (scene_path("congruent_triangles"), 30.0)
    assert monitor(scene="congruent_triangles", t_end=4.0).t_end == 4.0
    got = robot(scene="congruent_triangles", agent=3)
    assert (got.seed, got.pose_log) == (1003, None)  # no file: not declared
    assert robot(scene="congruent_triangles", agent=3, seed=0).seed == 0  # a seed like any other


def test_the_gains_are_checked_against_the_model_of_eqs_a1_a2():
    first = load_scene(scene_path("congruent_triangles")).model
    second = load_scene(scene_path(SECOND)).model
    assert check_gains(first, "realtime", {"kappa": 2.0, "mass": None}).kappa == 2.0
    assert check_gains(second, "realtime", {"gamma": 0.0}).gamma == 0.0  # undamped
    for model, mode, given, words in [
        (first, "realtime", {"gamma": 0.0}, "needs gamma > 0"),
        (first, "bridge", {"mass": 1.0}, "first order (A-2)"),
        (second, "bridge", {"gamma": 0.0}, "mode bridge"),
    ]:
        with pytest.raises(ParameterError, match=re.escape(words)):
            check_gains(model, mode, given)


@needs_ros
def test_a_runtime_gain_is_checked_against_the_model_then_applied_at_the_next_tick():
    """The set callback of a realtime agent: gamma 0 would divide (A-2) by zero and is refused
    with the reason; 0.5 is accepted and the next tick's model uses it."""
    from polymatch_ros.ros.agents.realtime import RealtimeAgent

    agent = object.__new__(RealtimeAgent)  # the callback and the tick alone, without a node
    scene = load_scene(scene_path("congruent_triangles"))
    agent.node = SimpleNamespace(has_parameter=lambda name: True)
    agent.scene, agent.model, agent.state = scene, scene.model, SimpleNamespace(t=1.0)
    agent.config, agent.pending = _agent_config(scene="congruent_triangles", mode="realtime"), {}
    agent.log = SimpleNamespace(warning=lambda text: None, info=lambda text: None)
    agent.rebuild_system = lambda: None
    refused = agent._on_set([SimpleNamespace(name="gamma", value=0.0)])
    assert not refused.successful and "needs gamma > 0, got 0" in refused.reason
    assert agent.pending == {} and not agent.apply_runtime()
    assert agent._on_set([SimpleNamespace(name="gamma", value=0.5)]).successful
    assert agent.model.gamma == 1.0 and agent.apply_runtime()
    assert (agent.model.gamma, agent.config.gamma, agent.model.kappa) == (0.5, 0.5, 1.0)
