"""`polymatch run` keeps within the DDS participants that LOCALHOST discovery reaches.

rmw_fastrtps probes the first 32 participant ports on 127.0.0.1; two participants beyond
them never meet (measured: 32 agent processes + runner + monitor never finish discovery).
"""

import pytest

from polymatch_ros.core.errors import PolymatchError
from polymatch_ros.ros.supervisor.plan import Packing
from polymatch_ros.ros.supervisor.runner import LOCALHOST_PARTICIPANTS, _agents_per_process


def _args(k=None, monitor=True):
    return Packing(requested=k, monitor=monitor, quiet=True)


def test_one_agent_per_process_while_it_fits():
    # 30 + runner + monitor = 32
    assert _agents_per_process(_args(), 30, localhost=True) == 1
    assert _agents_per_process(_args(monitor=False), 31, localhost=True) == 1


def test_packs_agents_when_processes_would_exceed_the_limit():
    k = _agents_per_process(_args(), 32, localhost=True)
    assert k == 2 and -(-32 // k) + 2 <= LOCALHOST_PARTICIPANTS
    k = _agents_per_process(_args(), 1000, localhost=True)
    assert -(-1000 // k) + 2 <= LOCALHOST_PARTICIPANTS


def test_explicit_k_beyond_the_limit_is_a_one_line_error():
    with pytest.raises(PolymatchError, match=r"34 DDS participants.*use -k 2 or more"):
        _agents_per_process(_args(k=1), 32, localhost=True)


def test_no_limit_without_localhost_discovery():
    assert _agents_per_process(_args(), 100, localhost=False) == 1
    assert _agents_per_process(_args(k=1), 100, localhost=False) == 1
