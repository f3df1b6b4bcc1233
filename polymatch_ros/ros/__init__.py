"""The ROS 2 layer: agent and monitor nodes, the launch-free runner, the message layer (wire).

Thin by design: every number these nodes compute comes from ``polymatch_ros.core``.
"""
