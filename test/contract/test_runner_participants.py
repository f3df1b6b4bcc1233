"""`polymatch run` packs its agents by measurement and keeps within the DDS participants that
LOCALHOST discovery reaches.

rmw_fastrtps probes the first 32 participant ports on 127.0.0.1; two participants beyond
them never meet (measured: 32 agent processes + runner + monitor never finish discovery).
Lockstep packs up to LOCKSTEP_AGENTS_PER_PROCESS agents a process (``docs/bench/packing.md``);
realtime up to REALTIME_AGENTS_PER_PROCESS (``docs/bench/realtime_scale.md``); bridge runs a
process per agent while they fit.
"""

import pytest

from polymatch_ros.core.errors import PolymatchError
from polymatch_ros.ros.supervisor.packing import (
    FULL_AGENT_NODES,
    LOCALHOST_PARTICIPANTS,
    LOCKSTEP_AGENTS_PER_PROCESS,
    REALTIME_AGENTS_PER_PROCESS,
    PackingAsked,
    choose_packing,
)


def _k(n, k=None, monitor=True, mode="realtime", localhost=True):
    packing = PackingAsked(requested=k, monitor=monitor, mode=mode)
    return choose_packing(packing, n, localhost=localhost).agents_per_process


@pytest.mark.parametrize("n,processes", [(2, 1), (8, 1), (64, 1), (1024, 1), (4096, 1),
                                         (4097, 2)])
def test_realtime_packs_by_the_measured_rule(n, processes):
    k = _k(n)
    assert k == min(n, REALTIME_AGENTS_PER_PROCESS) and -(-n // k) == processes
    asked = PackingAsked(None, True, mode="realtime")
    assert "docs/bench/realtime_scale.md" in choose_packing(asked, n, True).reason


def test_realtime_on_a_host_of_some_agents_keeps_a_process_per_agent():
    """--only: the other agents may speak only the public per-agent state topics."""
    packing = PackingAsked(requested=None, monitor=True, mode="realtime", whole=False)
    choice = choose_packing(packing, 8, True)
    assert choice.agents_per_process == 1 and "--only" in choice.reason


def test_realtime_k1_keeps_one_agent_a_process_bridge_always():
    # 30 + runner + monitor = 32
    assert _k(30, k=1) == 1
    assert _k(31, k=1, monitor=False) == 1
    assert _k(8, mode="bridge") == 1


def test_bridge_packs_agents_when_processes_would_exceed_the_limit():
    k = _k(32, mode="bridge")
    assert k == 2 and -(-32 // k) + 2 <= LOCALHOST_PARTICIPANTS
    k = _k(1000, mode="bridge")
    assert -(-1000 // k) + 2 <= LOCALHOST_PARTICIPANTS


@pytest.mark.parametrize("n,processes", [(2, 1), (8, 1), (256, 1), (1024, 1), (4096, 1),
                                         (4097, 2), (3 * 4096, 3)])
def test_lockstep_packs_by_the_measured_rule(n, processes):
    k = _k(n, mode="lockstep")
    assert k == min(n, LOCKSTEP_AGENTS_PER_PROCESS) and -(-n // k) == processes


def test_lockstep_stays_within_the_limit_beyond_the_measured_sizes():
    """Past the measured sizes the packing grows: the processes it makes (counted here, a
    process per run of k agents) with the runner and the monitor stay within the 32 ports."""
    assert LOCALHOST_PARTICIPANTS == 32                  # rmw_fastrtps's probe, not measured
    for n in (31 * LOCKSTEP_AGENTS_PER_PROCESS + 1, 40 * LOCKSTEP_AGENTS_PER_PROCESS, 10 ** 6):
        k = _k(n, mode="lockstep")
        processes = len(range(0, n, k))
        assert k > LOCKSTEP_AGENTS_PER_PROCESS and processes + 2 <= 32, (n, k)


def test_the_choice_says_why():
    packing = PackingAsked(requested=None, monitor=True, mode="lockstep")
    assert "docs/bench/packing.md" in choose_packing(packing, 64, True).reason
    assert choose_packing(PackingAsked(4, True), 64, True).reason == "-k 4 as asked"


def test_explicit_k_beyond_the_limit_is_a_one_line_error():
    with pytest.raises(PolymatchError, match=r"34 DDS participants.*use -k 2 or more"):
        _k(32, k=1, mode="lockstep")


def test_no_limit_without_localhost_discovery():
    assert _k(100, mode="bridge", localhost=False) == 1
    assert _k(100, k=1, localhost=False) == 1


@pytest.mark.parametrize("n,k,asked,level", [
    (8, None, "auto", "full"), (FULL_AGENT_NODES, None, "auto", "full"),
    (FULL_AGENT_NODES + 1, None, "auto", "lean"), (1024, None, "auto", "lean"),
    (1024, None, "full", "full"), (64, None, "none", "none"), (8, 1, "auto", "none"),
    (8, 1, "full", "none"),  # a process of one agent is that agent's node
])
def test_every_agent_gets_a_node_full_while_a_process_is_small_lean_beyond(n, k, asked, level):
    packing = PackingAsked(requested=k, monitor=True, mode="lockstep", agent_nodes=asked)
    assert choose_packing(packing, n, True).agent_nodes == level
