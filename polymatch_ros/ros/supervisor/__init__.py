"""What starts, watches, summarises and ends ROS processes: ``polymatch run`` (the
launch-free runner and its children), the lifecycle driver, the Fast DDS discovery server,
``polymatch set``, and the environment every child gets (loopback discovery, its own domain).
"""
