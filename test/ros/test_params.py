"""Bad ROS parameters are one line and exit code 2: every parameter of the agent and the monitor,
with a wrong type and out of its range, checked in-process (``params.check`` runs before the
nodes create any topic); the real processes are covered in test_ros_robustness.py."""

import pytest

from polymatch_ros.core.errors import ParameterError
from polymatch_ros.ros.nodes.params import AGENT, MONITOR, check

AGENT_NAMES = [
    "scene", "agent", "agents", "agents_per_process", "mode", "autostart", "integrator", "dt",
    "t_end", "rate", "kappa", "gamma", "time_scale", "start_time", "peer_timeout", "delay",
    "clock_offset_warn", "hold_final", "round_timeout", "stall_timeout", "peers_restart",
    "checkpoint", "discovery_timeout",
    "pose_subscribers", "frame_id", "max_linear_speed", "max_angular_speed", "max_linear_accel",
    "max_angular_accel", "pose_timeout", "pose_type", "cmd_type", "command_frame", "run_id",
]
MONITOR_NAMES = ["scene", "mode", "rate", "report_rate", "peer_timeout", "frame_id", "markers",
                 "t_end"]

STRING, BOOLEAN, INTEGER, NUMBER = ("expected a string", "expected a boolean",
                                    "expected an integer", "expected a number")
# (spec, parameter, a value of the wrong type, the words of the error)
TYPE_CASES = [
    ("agent", "scene", 1.5, STRING), ("agent", "agent", 2.5, INTEGER),
    ("agent", "agent", True, INTEGER), ("agent", "agents", 1.5, "expected a list of integers"),
    ("agent", "agents", [1, 2.5], "expected a list of integers"),
    ("agent", "agents_per_process", 2.5, INTEGER), ("agent", "mode", 1.5, STRING),
    ("agent", "autostart", 1.5, BOOLEAN), ("agent", "autostart", "true", BOOLEAN),
    ("agent", "integrator", 1.5, STRING), ("agent", "dt", "abc", NUMBER),
    ("agent", "dt", True, NUMBER), ("agent", "dt", float("nan"), NUMBER),
    ("agent", "t_end", "abc", NUMBER), ("agent", "t_end", float("inf"), NUMBER),
    ("agent", "rate", "abc", NUMBER), ("agent", "kappa", "abc", NUMBER),
    ("agent", "gamma", "abc", NUMBER), ("agent", "time_scale", "abc", NUMBER),
    ("agent", "start_time", "abc", NUMBER), ("agent", "peer_timeout", "abc", NUMBER),
    ("agent", "delay", "abc", NUMBER), ("agent", "clock_offset_warn", "abc", NUMBER),
    ("agent", "hold_final", "abc", NUMBER), ("agent", "round_timeout", "abc", NUMBER),
    ("agent", "stall_timeout", "abc", NUMBER), ("agent", "peers_restart", 1, BOOLEAN),
    ("agent", "checkpoint", 1.5, STRING), ("agent", "discovery_timeout", "abc", NUMBER),
    ("agent", "pose_subscribers", 2.5, INTEGER), ("agent", "frame_id", 1.5, STRING),
    ("agent", "max_linear_speed", "abc", NUMBER), ("agent", "max_angular_speed", "abc", NUMBER),
    ("agent", "max_linear_accel", "abc", NUMBER), ("agent", "max_angular_accel", "abc", NUMBER),
    ("agent", "pose_timeout", "abc", NUMBER), ("agent", "pose_type", 1.5, STRING),
    ("agent", "cmd_type", 1.5, STRING), ("agent", "command_frame", 1.5, STRING),
    ("agent", "run_id", 2.5, INTEGER),
    ("monitor", "scene", 1.5, STRING), ("monitor", "mode", 1.5, STRING),
    ("monitor", "rate", "abc", NUMBER), ("monitor", "report_rate", "abc", NUMBER),
    ("monitor", "peer_timeout", "abc", NUMBER), ("monitor", "frame_id", 1.5, STRING),
    ("monitor", "markers", 1.5, BOOLEAN), ("monitor", "t_end", "abc", NUMBER),
]
# (spec, parameter, lowest accepted, highest accepted, just below, just above, range text)
RANGE_CASES = [
    ("agent", "agent", 0, 1_000_000, -1, 1_000_001, "[0, 1e+06]"),
    ("agent", "agents_per_process", 1, 1_000_000, 0, 1_000_001, "[1, 1e+06]"),
    ("agent", "dt", 0.0, 1e6, -1e-9, 1.000001e6, "[0, 1e+06]"),
    ("agent", "t_end", 0.0, 1e12, -1e-9, 1.000001e12, "[0, 1e+12]"),
    ("agent", "rate", 0.01, 1e5, 0.0099, 100000.1, "[0.01, 100000]"),
    ("agent", "kappa", 0.0, 1e6, -1e-9, 1.000001e6, "[0, 1e+06]"),
    ("agent", "gamma", 0.0, 1e6, -1e-9, 1.000001e6, "[0, 1e+06]"),
    ("agent", "time_scale", 1e-6, 1e6, 9.9e-7, 1.000001e6, "[1e-06, 1e+06]"),
    ("agent", "start_time", -1.0, 1e12, -1.001, 1.000001e12, "[-1, 1e+12]"),
    ("agent", "peer_timeout", 0.001, 1e6, 0.00099, 1.000001e6, "[0.001, 1e+06]"),
    ("agent", "delay", 0.0, 1e6, -1e-9, 1.000001e6, "[0, 1e+06]"),
    ("agent", "clock_offset_warn", 0.0, 1e6, -1e-9, 1.000001e6, "[0, 1e+06]"),
    ("agent", "hold_final", 0.0, 1e6, -1e-9, 1.000001e6, "[0, 1e+06]"),
    ("agent", "round_timeout", 0.001, 1e6, 0.00099, 1.000001e6, "[0.001, 1e+06]"),
    ("agent", "stall_timeout", 0.001, 1e6, 0.00099, 1.000001e6, "[0.001, 1e+06]"),
    ("agent", "discovery_timeout", 0.0, 1e6, -1e-9, 1.000001e6, "[0, 1e+06]"),
    ("agent", "pose_subscribers", 0, 100_000, -1, 100_001, "[0, 100000]"),
    ("agent", "max_linear_speed", 0.0, 1e6, -1e-9, 1.000001e6, "[0, 1e+06]"),
    ("agent", "max_angular_speed", 0.0, 1e6, -1e-9, 1.000001e6, "[0, 1e+06]"),
    ("agent", "max_linear_accel", 0.0, 1e6, -1e-9, 1.000001e6, "[0, 1e+06]"),
    ("agent", "max_angular_accel", 0.0, 1e6, -1e-9, 1.000001e6, "[0, 1e+06]"),
    ("agent", "pose_timeout", 0.001, 1e6, 0.00099, 1.000001e6, "[0.001, 1e+06]"),
    ("agent", "run_id", 0, 2**31 - 1, -1, 2**31, "[0, 2.14748e+09]"),
    ("monitor", "rate", 0.01, 1e4, 0.0099, 10000.01, "[0.01, 10000]"),
    ("monitor", "report_rate", 0.01, 1e4, 0.0099, 10000.01, "[0.01, 10000]"),
    ("monitor", "peer_timeout", 0.001, 1e6, 0.00099, 1.000001e6, "[0.001, 1e+06]"),
    ("monitor", "t_end", 0.0, 1e12, -1e-9, 1.000001e12, "[0, 1e+12]"),
]
# (spec, parameter, the allowed values)
CHOICE_CASES = [
    ("agent", "mode", ("lockstep", "realtime", "bridge")),
    ("agent", "pose_type", ("pose", "odometry")),
    ("agent", "cmd_type", ("twist", "twist_stamped")),
    ("agent", "command_frame", ("world", "body")),
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
