"""Each node's typed configuration is its parameter table (names, types, defaults, in order);
the one renderer writes what rcl's YAML reads back as the same value (the round trip through a
real node: test/ros/test_params_over_ros.py); each `polymatch run` option that sets a node's
parameter agrees with the parameter's row (the shipped parameter files: test_param_files.py);
and an agent process loads and plans its scene once."""

import dataclasses
import re
import typing

import pytest
import yaml

from polymatch_ros.cli import build_parser
from polymatch_ros.ros.config.configs import (
    CONFIGS,
    AgentConfig,
    MonitorConfig,
    RecorderConfig,
    RobotConfig,
    config_from,
    render_value,
    ros_args,
)
from polymatch_ros.ros.config.params import AGENT, MONITOR, RECORDER, ROBOT, check, check_value
from polymatch_ros.ros.supervisor.plan import (
    NODE_OPTIONS,
    OWN_DEFAULTS,
    RunOptions,
    node_parameter,
)

TABLES = {AgentConfig: AGENT, MonitorConfig: MONITOR, RobotConfig: ROBOT,
          RecorderConfig: RECORDER}
#: a row's kind -> the field's type (a row naming only a type: None until resolved or given)
TYPES = {bool: bool, int: int, float: float, str: str, list: list[int]}


def test_every_table_has_its_configuration():
    assert {cls.table for cls in CONFIGS} == set(TABLES.values())
    assert all(cls.table is table for cls, table in TABLES.items())


@pytest.mark.parametrize("cls", CONFIGS, ids=lambda c: c.__name__)
def test_a_configuration_is_its_table_names_types_and_defaults(cls):
    """One field per row, in the table's order; the row's type (optional where the node
    resolves it); the row's default, or None where the row names only a type."""
    fields = dataclasses.fields(cls)
    assert [f.name for f in fields] == [p.name for p in TABLES[cls]]
    hints = typing.get_type_hints(cls)
    for f, p in zip(fields, TABLES[cls]):
        want = TYPES[p.kind] if p.fixed else TYPES[p.kind] | None
        assert hints[f.name] == want, f.name
        if p.fixed:
            assert type(f.default) is type(p.default) and f.default == p.default, f.name
        else:
            assert f.default is None, f.name


@pytest.mark.parametrize("value,text", [
    (True, "true"), (False, "false"), (0, "0"), (2**31 - 1, "2147483647"),
    (50.0, "50.0"), (1e-12, "1e-12"), (1e6, "1000000.0"), (0.1 + 0.2, "0.30000000000000004"),
    ([4, 5], "[4,5]"), ([], "[]"), ("/tmp/scene.yaml", "/tmp/scene.yaml"), ("world", "world"),
    ("true", "'true'"), ("yes", "'yes'"), ("1", "'1'"), ("1e-3", "'1e-3'"), ("", "''"),
    ("a b", "'a b'"), ("it's", "'it''s'"), ("x: y", "'x: y'"), ("[1]", "'[1]'"),
    (["/a/b", "true"], "[/a/b,'true']"),
])
def test_a_value_is_rendered_as_yaml_reads_it(value, text):
    """Written out here: the YAML each value needs; a float always reads as a float (a dot or
    an exponent: rcl takes 1e-12 for a double), a string that YAML would read as another type
    or could not read plain is quoted."""
    assert render_value(value) == text
    if isinstance(value, float):
        assert float(text) == value and ("." in text or "e" in text)
    elif isinstance(value, str) and text.startswith("'"):
        assert yaml.safe_load(text) == value  # a quoted scalar is a string whatever it holds


def test_ros_args_give_what_differs_from_the_table_remaps_first_the_file_before_values():
    config = AgentConfig(scene="/s.yaml", agent=3, rate=50.0, time_scale=2, autostart=False,
                         checkpoint=None)
    args = ros_args(config, namespace="/ens", node="agent_3",
                    remaps={"cmd_vel": "robot_3/cmd_vel"}, params_file="/p.yaml")
    assert args == ["-r", "__ns:=/ens", "-r", "cmd_vel:=robot_3/cmd_vel", "-r",
                    "__node:=agent_3", "--params-file", "/p.yaml", "-p", "scene:=/s.yaml",
                    "-p", "agent:=3", "-p", "autostart:=false", "-p", "time_scale:=2.0"]
    assert ros_args(RecorderConfig(output="/o.mcap"), lists={"topics": ["/a", "/b"]}) == [
        "-p", "output:=/o.mcap", "-p", "topics:=[/a,/b]"]


@pytest.mark.parametrize("option", sorted(NODE_OPTIONS))
def test_a_run_option_that_sets_a_node_parameter_agrees_with_its_row(option):
    """The option exists (its dest is the RunOptions field), its parameter is a row of its
    node's table, its default passes the row's checks and is the row's (unless the option
    keeps its own, ``OWN_DEFAULTS``, or the node resolves it), its choices are the row's."""
    run = next(a for a in build_parser()._subparsers._group_actions[0].choices["run"]._actions
               if a.dest == option)
    p = node_parameter(option)
    assert NODE_OPTIONS[option][1] == p.name
    field = next(f for f in dataclasses.fields(RunOptions) if f.name == option)
    assert run.default == field.default  # the parser's default is the options record's
    if run.default is not None:
        assert check_value(p, run.default) == run.default
        if option not in OWN_DEFAULTS:
            assert p.fixed and run.default == p.default
    if run.choices is not None:
        assert p.choices is not None and set(run.choices) <= set(p.choices)


def test_an_option_out_of_its_parameter_range_is_refused_before_anything_starts():
    from polymatch_ros.core.errors import ParameterError
    from polymatch_ros.ros.supervisor.plan import build_run_plan

    for options, words in [
        (RunOptions("congruent_triangles", mode="realtime", rate=0.001), "--rate: 0.001 is out "
         "of range [0.01, 100000]"),
        (RunOptions("congruent_triangles", run_id=2**31), "--run-id: 2.14748e+09 is out of "
         "range [0, 2.14748e+09]"),
    ]:
        with pytest.raises(ParameterError, match=re.escape(words)):
            build_run_plan(options)


def test_an_agent_process_loads_and_plans_its_scene_once(monkeypatch):
    """Resolving the parameters and configuring the agent (what ``make_agent`` and the lifecycle
    configure transition run, without a node): one scene load, one numerical plan, in every
    mode (counted by wrapping the core's functions)."""
    from polymatch_ros.core.scenes import scene as scenes
    from polymatch_ros.core.stepping import simulate
    from polymatch_ros.ros.agents.bridge import BridgeAgent
    from polymatch_ros.ros.agents.lockstep import LockstepAgent
    from polymatch_ros.ros.agents.realtime import RealtimeAgent
    from polymatch_ros.ros.config.resolve import resolve_agent

    calls = {"load_scene": 0, "choose_numerics": 0}

    def counted(module, name):
        real = getattr(module, name)

        def wrapper(*args, **kwargs):
            calls[name] += 1
            return real(*args, **kwargs)
        monkeypatch.setattr(module, name, wrapper)

    counted(scenes, "load_scene")
    counted(simulate, "choose_numerics")
    for cls, mode in [(LockstepAgent, "lockstep"), (RealtimeAgent, "realtime"),
                      (BridgeAgent, "bridge")]:
        calls.update(load_scene=0, choose_numerics=0)
        given = config_from(AgentConfig, check(AGENT, {"scene": "congruent_triangles",
                                                       "mode": mode, "agent": 2}))
        resolved = resolve_agent(given)
        agent = object.__new__(cls)  # AgentBase._configure alone: no node, no topic
        agent.log = None
        agent._configure(resolved)
        assert calls == {"load_scene": 1, "choose_numerics": 1}, mode
        assert agent.layout.local == [2] and agent.scene.t_end == 30.0  # the scene file's
        assert agent.numerics is resolved.numerics
