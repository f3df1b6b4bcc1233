"""`polymatch echo TOPIC`: a launch-free stand-in for `ros2 topic echo` (ros2cli is not on PyPI).

    polymatch echo /polymatch/diameter                     print every value, YAML-like
    polymatch echo /polymatch/diameter --until-below 1e-6  exit 0 once a value is below 1e-6
    polymatch echo /diagnostics --count 3

The message type is read from the ROS graph (like ros2 topic echo) and the
subscription adopts the publisher's durability, so a late echo of a latched
topic still prints its last value.  It runs in the caller's ROS domain (ROS_DOMAIN_ID, ROS's
default 0 when unset) with the discovery of `polymatch run` (loopback unless the caller set
ROS_AUTOMATIC_DISCOVERY_RANGE), and ends by itself: after --count messages, --until-below,
--timeout seconds (exit 1), or, without --timeout, when no message came within
``FIRST_MESSAGE_SECONDS`` (exit 1; the error names the domain and discovery range it listened
in).  Once the topic is heard and no --timeout was given, it prints until Ctrl-C.
"""

from __future__ import annotations

import json
import os
import sys
import time
from typing import TYPE_CHECKING, Any, TextIO

from ...core.errors import PolymatchError
from ..process.shell import ros_main
from ..wire.recording import message_class
from ..wire.topics import matching_profile

if TYPE_CHECKING:
    from rclpy.qos import QoSProfile
    from rclpy.topic_endpoint_info import TopicEndpointInfo

#: how long `polymatch echo` waits for a topic's first message when no --timeout is given (s)
FIRST_MESSAGE_SECONDS = 10.0
#: the echo's history: a few messages, it prints as they come
ECHO_DEPTH = 10


def listening_in() -> str:
    """Where this process listens: its ROS domain and discovery range, as its errors say it."""
    domain = os.environ.get("ROS_DOMAIN_ID", "").strip()
    where = f"ROS_DOMAIN_ID {domain}" if domain else (
        "ROS_DOMAIN_ID 0 (ROS's default: ROS_DOMAIN_ID is not set)")
    reach = os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE") or "SUBNET (ROS's default)"
    return f"{where}, discovery range {reach}"


def message_to_lines(msg: Any, indent: str = "") -> list[str]:
    """A YAML-like rendering of a ROS message (nested fields, arrays shortened)."""
    lines = []
    for name in msg.get_fields_and_field_types():
        value = getattr(msg, name)
        if hasattr(value, "get_fields_and_field_types"):
            lines.append(f"{indent}{name}:")
            lines.extend(message_to_lines(value, indent + "  "))
        elif isinstance(value, (list, tuple)) or (
            hasattr(value, "__len__") and not isinstance(value, str)
        ):
            items = list(value)
            if items and hasattr(items[0], "get_fields_and_field_types"):
                lines.append(f"{indent}{name}:")
                for item in items:
                    sub = message_to_lines(item, indent + "  ")
                    lines.append(f"{indent}- {sub[0].strip()}" if sub else f"{indent}-")
                    lines.extend(sub[1:])
            else:
                shown = ", ".join(
                    repr(float(v)) if isinstance(v, float) else str(v) for v in items[:16]
                )
                more = ", ..." if len(items) > 16 else ""
                lines.append(f"{indent}{name}: [{shown}{more}]")
        elif isinstance(value, float):
            lines.append(f"{indent}{name}: {value!r}")
        else:
            lines.append(f"{indent}{name}: {value}")
    return lines


def message_to_dict(msg: Any) -> dict[str, Any]:
    """A ROS message as plain data (nested messages as dicts, arrays as lists): one JSON line
    of ``polymatch echo --json``."""
    out: dict[str, Any] = {}
    for name in msg.get_fields_and_field_types():
        value = getattr(msg, name)
        if hasattr(value, "get_fields_and_field_types"):
            out[name] = message_to_dict(value)
        elif hasattr(value, "__len__") and not isinstance(value, (str, bytes)):
            out[name] = [message_to_dict(v) if hasattr(v, "get_fields_and_field_types")
                         else (v.item() if hasattr(v, "item") else v) for v in value]
        else:
            out[name] = value.item() if hasattr(value, "item") else value
    return out


class Echo:
    """Print every message of ``topic`` until --count, --until-below or --timeout (exit 1)."""

    def __init__(self, topic: str, count: int | None = None, until_below: float | None = None,
                 timeout: float | None = None, stream: TextIO = sys.stdout,
                 as_json: bool = False) -> None:
        from rclpy.node import Node

        self.node = Node(f"echo_{os.getpid()}")
        self.topic, self.count, self.until_below = topic, count, until_below
        # without --timeout: only the first message is waited for at most FIRST_MESSAGE_SECONDS
        self.bounded = timeout is not None
        self.timeout = timeout if timeout is not None else FIRST_MESSAGE_SECONDS
        self.stream, self.as_json = stream, as_json
        self.deadline: float | None = time.monotonic() + self.timeout
        self.seen = 0
        self.done = False

    def _spin(self) -> None:
        import rclpy

        rclpy.spin_once(self.node, timeout_sec=0.1)

    def _qos(self) -> tuple[type, QoSProfile]:
        """The publishers' type, and a QoS that matches them (a latched topic's last value too)."""
        infos: list[TopicEndpointInfo] = []
        while not infos:
            infos = self.node.get_publishers_info_by_topic(self.topic)
            if self.deadline is not None and time.monotonic() > self.deadline:
                raise PolymatchError(f"no publisher on {self.topic} within {self.timeout:g} s in "
                                     f"{listening_in()}")
            self._spin()
        qos = matching_profile([i.qos_profile for i in infos], ECHO_DEPTH)
        return message_class(infos[0].topic_type), qos

    def _receive(self, msg: Any) -> None:
        self.seen += 1
        if not self.bounded:
            self.deadline = None  # heard: print until --count, --until-below or Ctrl-C
        if self.as_json:
            self.stream.write(json.dumps(message_to_dict(msg)) + "\n")
        else:
            self.stream.write("\n".join(message_to_lines(msg)) + "\n---\n")
        self.stream.flush()
        if self.count is not None and self.seen >= self.count:
            self.done = True
        if (
            self.until_below is not None
            and hasattr(msg, "data")
            and float(msg.data) < self.until_below
        ):
            self.done = True

    def run(self) -> int:
        cls, qos = self._qos()
        self.node.create_subscription(cls, self.topic, self._receive, qos)
        while not self.done:
            if self.deadline is not None and time.monotonic() > self.deadline:
                if not self.seen:
                    raise PolymatchError(f"{self.topic}: no message within {self.timeout:g} s "
                                         f"in {listening_in()}")
                below = (
                    f", none below {self.until_below:g}" if self.until_below is not None else ""
                )
                raise PolymatchError(
                    f"{self.topic}: stopped after {self.timeout:g} s and "
                    f"{self.seen} message(s){below}"
                )
            self._spin()
        return 0

    def destroy(self) -> None:
        self.node.destroy_node()


def echo(topic: str, count: int | None = None, until_below: float | None = None,
         timeout: float | None = None, stream: TextIO = sys.stdout, as_json: bool = False) -> int:
    """Print the messages of ``topic`` (absolute) until ``count`` messages, a value below
    ``until_below``, or ``timeout`` seconds (an error; None: ``FIRST_MESSAGE_SECONDS`` without
    a message); the exit code."""
    return ros_main(
        lambda argv: Echo(topic, count, until_below, timeout, stream, as_json), "polymatch",
        ["polymatch"]
    )
