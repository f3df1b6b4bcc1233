"""Bad ROS parameters are one line and exit code 2: every parameter of the agent and the monitor,
with a wrong type and out of its range, checked in-process (``params.check`` runs before the
nodes create any topic); the real processes are covered in test_ros_robustness.py."""

import pytest

from polymatch_ros.core.errors import ParameterError
from polymatch_ros.ros.params import AGENT, MONITOR, check

CASES = []
for spec_name, spec in (("agent", AGENT), ("monitor", MONITOR)):
    for p in spec:
        wrong = 1.5 if isinstance(p.default, (str, bool)) or p.default is None else "abc"
        if isinstance(p.default, int) and not isinstance(p.default, bool):
            wrong = 2.5
        CASES.append((spec_name, p.name, wrong, "expected"))
        if p.bounds is not None:
            CASES.append((spec_name, p.name, p.bounds[1] * 2 + 1, "out of range"))
            below = p.bounds[0] - 1
            CASES.append(
                (
                    spec_name,
                    p.name,
                    below if isinstance(p.default, float) else int(below),
                    "out of range",
                )
            )
        if p.choices is not None:
            CASES.append((spec_name, p.name, "fast", "expected " + " or ".join(p.choices)))


@pytest.mark.parametrize("spec_name,name,value,expect", CASES)
def test_bad_parameter_is_one_line_parameter_error(spec_name, name, value, expect):
    spec = AGENT if spec_name == "agent" else MONITOR
    values = {"scene": "congruent_triangles", name: value}
    with pytest.raises(ParameterError) as info:
        check(spec, values)
    text = str(info.value)
    assert info.value.exit_code == 2 and len(text.splitlines()) == 1 and expect in text, text
    assert repr(name) in text or name == "scene"


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
    from polymatch_ros.ros.param_set import _not_found
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
