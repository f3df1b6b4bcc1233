"""Where a run's processes find each other: the environment every ROS process gets (loopback
discovery, the run's domain, the DDS profile), discovery specs across hosts, and the Fast DDS
discovery server.
"""
