"""The ROS nodes the package runs as processes: the agent (``agent``, whose classes are in
``ros.agents``), the monitor and its outputs, the simulated robot, the recorder, the echo tool, the
Match action server and the simulated clock.  Every number they compute comes from
``polymatch_ros.core``; every topic's name, type and QoS from ``polymatch_ros.ros.wire``.
"""
