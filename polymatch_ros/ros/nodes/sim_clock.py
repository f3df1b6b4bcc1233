"""``/clock``: a lockstep run's simulated time, for tools started with ``use_sim_time:=true``.

One process of a run publishes it: the monitor, which already follows the simulated time (the
latest step every agent has completed).  Each report publishes the time of the step it
reports, the very stamp of that step's poses (integer nanoseconds), so a tool that follows
``/clock`` lines up with the stamps; between reports the clock holds.  It never goes back:
a time at or before the last one published is skipped.  The agents do not publish it: one
writer per run keeps the clock single-valued, and a report costs the lockstep rounds nothing.

The writer's QoS is the clock's of ROS (rclcpp's ``ClockQoS``, what ``ros2 bag play --clock``
offers): the newest value only, BEST_EFFORT, VOLATILE; rclpy's and rclcpp's time sources read
it so.  ``/clock`` is absolute, one per ROS domain: two ensembles sharing a domain remap one
(``--ros-args -r /clock:=/other/clock``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from rclpy.node import Node

CLOCK_TOPIC = "/clock"


class SimClock:
    """The ``/clock`` writer of one node: ``advance(ns)`` publishes a later simulated time."""

    def __init__(self, node: Node) -> None:
        from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
        from rosgraph_msgs.msg import Clock  # type: ignore[import-untyped]

        qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                         reliability=ReliabilityPolicy.BEST_EFFORT,
                         durability=DurabilityPolicy.VOLATILE)
        self.message = Clock
        self.publisher = node.create_publisher(Clock, CLOCK_TOPIC, qos)
        self.last_ns = -1

    def advance(self, ns: int) -> bool:
        """Publish the simulated time ``ns`` (nanoseconds) if it is later than the last one
        published; whether it was."""
        if ns <= self.last_ns:
            return False
        self.last_ns = ns
        msg = self.message()
        msg.clock.sec, msg.clock.nanosec = divmod(ns, 1_000_000_000)
        self.publisher.publish(msg)
        return True

    def destroy(self, node: Node) -> None:
        node.destroy_publisher(self.publisher)
