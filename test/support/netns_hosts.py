"""Several "hosts" on one machine for the tests: benchmarks/hosts/namespaces.py (network
namespaces joined by a bridge in a namespace of its own), and ``provided_hosts``, a pytest
fixture's body.

    with NetnsHosts(3) as net:              # or the pytest fixture in a test module
        net.addresses                       # ['10.213.7.1', '10.213.7.2', '10.213.7.3']
        net.add_loss(1, percent=10)         # nftables: drop 10% of what host 1 receives
"""

from benchmarks.hosts.namespaces import (  # noqa: F401 (the tests' names)
    DDS_FILTER,
    LOSS_TABLE,
    PREFIX,
    Capture,
    NetnsHosts,
    namespaces,
    remove_stale,
    root_interfaces,
    unavailable_reason,
)


def provided_hosts(count, tools=()):
    """A fixture's body: ``count`` namespace hosts for one test (skipped where they or ``tools``
    are unavailable), closed afterwards with no namespace left over, and no Fast DDS file of a
    process that died meanwhile left in /dev/shm, which the namespaces share
    (``supervisor.shm``).  The hosts' processes run in one of the suite's ROS slots
    (``ros_harness.ros_slot``)."""
    import pytest
    from ros_harness import ros_slot

    from polymatch_ros.ros.supervisor.shm import ShmSweep

    reason = unavailable_reason(tools)
    if reason:
        pytest.skip(reason)
    with ros_slot():
        hosts, sweep = NetnsHosts(count), ShmSweep()
        try:
            hosts.create()
            yield hosts
        finally:
            hosts.close()
            sweep.remove_dead()
            assert hosts.left_over() == []
