"""What runs inside a ROS process: the agent (one class per mode), the monitor, the simulated
robot, the echo tool, their parameters and services, and the lean readers and writers of the
hot paths.  Every number they compute comes from ``polymatch_ros.core``; every topic's name,
type and QoS from ``polymatch_ros.ros.wire``.
"""
