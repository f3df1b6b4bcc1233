"""The families that measure the ROS node set: `polymatch run` in lockstep, realtime and bridge
mode, packing and scale, graphs, lossy hosts, faults and watching; with the runs'
shared launcher (``ros_runs``) and the bare transport's limit (``bare_exchange``)."""
