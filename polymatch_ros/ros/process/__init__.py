"""The process shell every ROS process of the package runs in: start (``shell.ros_main``), the
bounded teardown and the native exit timer that ends a process Fast DDS holds at exit.
"""
