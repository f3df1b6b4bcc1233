"""The ROS 2 layer, in three wings whose imports run one way (``test_layering``):

    supervisor/  starts, watches, summarises and ends processes (``polymatch run``)
    nodes/       what runs inside a process: agents, monitor, robot, echo
    wire/        every topic's name, type and QoS; codecs; run records

Thin by design: every number these nodes compute comes from ``polymatch_ros.core``.
"""
