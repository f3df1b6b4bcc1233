"""How often the monitor reports (``nodes.monitor.quiet_after``): a report that took c s of CPU
keeps the next ones quiet for c / REPORT_CPU_SHARE s, so the reports take at most that share of
a core, but never for more than MOST_QUIET_SECONDS, so that whoever watches gets a report a
second at the least (a first report that loads scipy's graph routines, a thousand agents).

The oracle is the arithmetic of the rule written out here with the shipped constants' values
(a fiftieth of a core, a second)."""

import pytest
from ros_harness import needs_ros

pytestmark = needs_ros


@pytest.mark.parametrize("spent, quiet_for", [
    (0.0, 0.0),        # a free report: the next one at its period
    (0.002, 0.1),      # 2 ms of CPU: 100 ms quiet (a fiftieth of a core)
    (0.01, 0.5),       # 10 ms: half a second
    (0.02, 1.0),       # 20 ms: the cap exactly
    (0.15, 1.0),       # a first report that loaded what it needs: capped at 1 s, not 7.5
])
def test_a_report_keeps_the_next_quiet_for_its_cpu_over_the_share_at_most_a_second(
        spent, quiet_for):
    from polymatch_ros.ros.nodes.monitor import MOST_QUIET_SECONDS, REPORT_CPU_SHARE, quiet_after

    assert (REPORT_CPU_SHARE, MOST_QUIET_SECONDS) == (0.02, 1.0)
    assert quiet_after(0.0, 100.0, spent) == pytest.approx(100.0 + quiet_for, abs=1e-12)


def test_a_quiet_time_already_set_is_never_shortened():
    from polymatch_ros.ros.nodes.monitor import quiet_after

    assert quiet_after(105.0, 100.0, 0.002) == 105.0
    assert quiet_after(100.05, 100.0, 0.01) == pytest.approx(100.5)
