"""Shared fixtures: ``ros`` gives a test its own loopback-only ROS world (see ros_harness.py)."""

import pytest
from ros_harness import ros  # noqa: F401


@pytest.hookimpl(wrapper=True, tryfirst=True)
def pytest_runtest_makereport(item, call):
    """Record each phase's report on the item, so fixtures can tell a failed test at teardown."""
    report = yield
    setattr(item, "rep_" + report.when, report)
    return report
