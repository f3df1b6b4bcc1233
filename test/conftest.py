"""Shared fixtures: ``ros`` gives a test its own loopback-only ROS world (see ros_harness.py)."""

from ros_harness import ros  # noqa: F401
