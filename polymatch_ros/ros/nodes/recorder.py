"""The recorder: a node that writes the messages of chosen topics to an MCAP file.

    polymatch record /polymatch/diameter /diagnostics -o run.mcap --duration 30
    python -m polymatch_ros.ros.nodes.recorder --ros-args -p output:=/tmp/run.mcap \\
        -p topics:="[/polymatch/diameter]"

Every subscription is ``raw``: it takes the serialized CDR bytes, which go into the file as
they came (``wire.recording.RecordingWriter``), stamped with the time they were received and
the time they were sent.  A topic given with its type and writer profile (``types``, ``qos``;
what ``polymatch run --record`` passes) is subscribed to at once, its channel stating the
table's profile as what its writers offer, so a lockstep ensemble that
waits for its pose readers (``pose_subscribers``) loses no step; any other topic is taken
with the type and QoS its publishers offer once they appear, its channel stating their
profiles (as ``ros2 bag record`` does).

The recorder ends on SIGINT or SIGTERM (its normal end, exit 0), after ``duration`` seconds,
or at an error; it then takes what its readers still hold (at most ``DRAIN_SECONDS``),
writes the file's summary and closes it before the DDS teardown, which its watchdog bounds
(``process.shell.ros_main``), so the file is complete whatever the teardown does.
"""

from __future__ import annotations

import os
import signal
import sys
import time
from collections.abc import Sequence
from types import FrameType
from typing import TYPE_CHECKING, Any

from ...core.errors import ParameterError
from .. import wire
from ..config.configs import RecorderConfig, read_config
from ..process.shell import NodeApp, ros_main
from ..wire.recording import (
    RECORDER_DEPTH,
    SCENE_ATTACHMENT,
    RecordedTopic,
    RecordingWriter,
    message_class,
    recorder_qos,
)
from ..wire.topics import QOS, matching_profile, qos_profiles

if TYPE_CHECKING:
    from rclpy.node import Node
    from rclpy.qos import QoSProfile

#: string arrays, aligned: topic names; their types and writers' QoS keys ('' = as offered)
LISTS = ("topics", "types", "qos")
DRAIN_SECONDS = 1.0
DISCOVERY_PERIOD = 0.5


def declare_lists(node: Node) -> dict[str, list[str]]:
    """The string-array parameters ``LISTS`` (unset: empty), checked aligned."""
    from rcl_interfaces.msg import ParameterDescriptor
    from rclpy.exceptions import ParameterUninitializedException
    from rclpy.parameter import Parameter

    texts = {"topics": "absolute names of the topics to record",
             "types": "their types (pkg/msg/Type; '' = from the graph)",
             "qos": "their writers' profile in wire.topics.QOS ('' = adapt to the publishers)"}
    out: dict[str, list[str]] = {}
    for name in LISTS:
        node.declare_parameter(name, Parameter.Type.STRING_ARRAY,
                               ParameterDescriptor(description=texts[name], read_only=True))
        try:
            out[name] = list(node.get_parameter(name).value)
        except ParameterUninitializedException:
            out[name] = []
    if not out["topics"]:
        raise ParameterError("parameter 'topics': name at least one topic to record")
    for name in ("types", "qos"):
        if out[name] and len(out[name]) != len(out["topics"]):
            raise ParameterError(f"parameter {name!r}: one entry per topic "
                                 f"({len(out['topics'])}), got {len(out[name])}")
    return out


def recorded_topics(lists: dict[str, list[str]]) -> list[RecordedTopic]:
    """The aligned lists as RecordedTopics; a relative name or unknown QoS key is an error."""
    n = len(lists["topics"])
    out = []
    for name, type_, qos in zip(lists["topics"], lists["types"] or [""] * n,
                                lists["qos"] or [""] * n):
        if not name.startswith("/"):
            raise ParameterError(f"parameter 'topics': {name!r} is not absolute")
        if qos and qos not in QOS:
            raise ParameterError(f"parameter 'qos': unknown profile {qos!r}")
        if type_:
            message_class(type_)  # an unknown type is an error before the file is opened
        out.append(RecordedTopic(name, type_, qos))
    return out


class Recorder(NodeApp):
    """Subscribes (raw) to the topics, writes each message to the MCAP file as it comes."""

    def __init__(self, node: Node, config: RecorderConfig,
                 topics: Sequence[RecordedTopic]) -> None:
        from rclpy.executors import SingleThreadedExecutor

        if not config.output:
            raise ParameterError("parameter 'output' is required (an .mcap file)")
        self.node, self.config = node, config
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(node)
        self.stopping = False
        for sig in (signal.SIGINT, signal.SIGTERM):  # after rclpy's: the file is ours to end
            signal.signal(sig, self._stop)
        self.file = RecordingWriter(config.output)
        self._attach_scene()
        self.waiting = [t for t in topics if not (t.type and t.qos)]
        offered = qos_profiles()
        self.subscriptions = [
            self._subscribe(t.name, t.type, recorder_qos(t.qos), [offered[t.qos]])
            for t in topics if t.type and t.qos]
        self.started = time.monotonic()

    def _stop(self, sig: int, frame: FrameType | None) -> None:
        self.stopping = True

    def _attach_scene(self) -> None:
        path = self.config.scene_file
        if not path:
            return
        from ...core.scenes.scene import resolve_scene_path
        from ...core.scenes.yamlfile import read_scene_file

        path = resolve_scene_path(path)
        now = time.time_ns()
        self.file.attach(SCENE_ATTACHMENT, read_scene_file(path).encode(), "application/yaml", now)
        self.file.metadata({"scene": os.path.abspath(path), "t_end": repr(self.config.t_end),
                            "mode": self.config.mode})

    def _subscribe(self, name: str, type_: str, qos: QoSProfile,
                   offered: Sequence[QoSProfile]) -> Any:
        """A raw reader of ``name`` with ``qos``, written to a channel whose writers offer
        ``offered``."""
        channel = self.file.channel(name, type_, offered)
        write = self.file.write

        def take(data: bytes, info: dict[str, Any]) -> None:
            received = info.get("received_timestamp") or time.time_ns()
            write(channel, data, received, info.get("source_timestamp") or received)

        return self.node.create_subscription(message_class(type_), name, take, qos, raw=True)

    def _discover(self) -> None:
        """Subscribe to the waiting topics whose publishers have appeared, as they offer."""
        for topic in list(self.waiting):
            infos = self.node.get_publishers_info_by_topic(topic.name)
            if not infos:
                continue
            qos = matching_profile([i.qos_profile for i in infos], RECORDER_DEPTH)
            self.subscriptions.append(
                self._subscribe(topic.name, topic.type or infos[0].topic_type, qos,
                                [i.qos_profile for i in infos]))
            self.waiting.remove(topic)

    def run(self) -> int:
        duration = self.config.duration
        next_look = 0.0
        while not self.stopping:
            now = time.monotonic()
            if duration and now - self.started >= duration:
                break
            if self.waiting and now >= next_look:
                self._discover()
                next_look = now + DISCOVERY_PERIOD
            self.executor.spin_once(timeout_sec=0.1)
        self.drain()
        self.file.finish()
        return 0

    def drain(self) -> None:
        """Take what the readers still hold: until a spin takes nothing, DRAIN_SECONDS at most."""
        end = time.monotonic() + DRAIN_SECONDS
        before = -1
        while self.file.messages != before and time.monotonic() < end:
            before = self.file.messages
            self.executor.spin_once(timeout_sec=0.05)

    def report(self) -> None:
        """The file is finished before anything else (also after an error); one line."""
        self.file.finish()
        missing = ", ".join(t.name for t in self.waiting)
        note = f"; never published: {missing}" if missing else ""
        print(f"recorder: {self.file.describe()}{note}", flush=True)


def make_recorder(argv: list[str] | None = None) -> Recorder:
    from rclpy.node import Node

    node = Node("recorder", namespace=wire.namespace(wire.DEFAULT_ENSEMBLE))
    topics = recorded_topics(declare_lists(node))
    return Recorder(node, read_config(node, RecorderConfig), topics)


def main(args: list[str] | None = None) -> int:
    # the recorder runs until it is stopped: SIGINT and SIGTERM are its normal end
    return ros_main(make_recorder, "recorder", args, interrupted_exit=0)


if __name__ == "__main__":
    sys.exit(main())
