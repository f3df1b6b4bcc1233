"""The three modes are said once (``wire.modes``), and every place that offers a mode offers
exactly those: the command line's ``--mode``, the agent's and the monitor's ``mode`` parameter,
and the agent class of each mode.  The oracle is the table below, written from the guide's
description of the modes (docs/guide/ros-interface.md), not from the code."""

import pytest

from polymatch_ros.cli import build_parser
from polymatch_ros.cli.reference import subcommands
from polymatch_ros.core.errors import ParameterError
from polymatch_ros.ros.config.params import AGENT, MONITOR
from polymatch_ros.ros.nodes.agent import agent_class
from polymatch_ros.ros.wire.modes import Mode, mode_of

#: mode: (equals the centralised run, ticks on the wall clock, drives robots, packs agents,
#: the monitor follows it as, simulated seconds a tick at 20 Hz and time scale 2)
GUIDE = {
    "lockstep": (True, False, False, True, "lockstep", None),
    "realtime": (False, True, False, True, "realtime", 0.1),
    "bridge": (False, True, True, False, "realtime", 0.05),
}


@pytest.mark.parametrize("name", sorted(GUIDE))
def test_each_mode_does_what_the_guide_says(name):
    exact, ticks, robots, packs, monitored, tick = GUIDE[name]
    mode = mode_of(name)
    assert (mode.exact, mode.ticks, mode.drives_robots, mode.packs) == (exact, ticks, robots,
                                                                         packs)
    assert mode.monitored_as == monitored
    if tick is not None:
        assert mode.tick_step(20.0, 2.0) == pytest.approx(tick)


def test_every_place_that_offers_a_mode_offers_the_same_three():
    run = subcommands(build_parser())["run"]
    option = next(a for a in run._actions if "--mode" in a.option_strings)
    agent = next(p for p in AGENT if p.name == "mode")
    monitor = next(p for p in MONITOR if p.name == "mode")
    assert set(option.choices) == set(agent.choices) == set(GUIDE) == {m.value for m in Mode}
    assert set(monitor.choices) == {GUIDE[m][4] for m in GUIDE}
    assert option.default == agent.default == "lockstep"


@pytest.mark.parametrize("name,cls", [("lockstep", "LockstepAgent"),
                                      ("realtime", "RealtimeAgent"), ("bridge", "BridgeAgent")])
def test_each_mode_has_its_own_agent_class_named_for_it(name, cls):
    chosen = agent_class(name)
    assert chosen.__name__ == cls and chosen.mode == name


def test_another_mode_is_refused_in_one_line():
    with pytest.raises(ParameterError, match=r"^mode: 'warp' is not one of lockstep, realtime, "
                                             r"bridge$"):
        mode_of("warp")
