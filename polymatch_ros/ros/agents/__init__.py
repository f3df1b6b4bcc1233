"""The agent inside a ROS process, one class per mode (lockstep, realtime, bridge) over a common
base: the processes' hosted agents and their services, the lifecycle wrapper, the lockstep stage
links and the realtime peer table.  ``ros.nodes.agent`` is the node that runs them.
"""
