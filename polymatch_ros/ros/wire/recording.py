"""MCAP recordings of an ensemble's topics, laid out as rosbag2 writes them.

One MCAP file (``polymatch run --record``, ``polymatch record``): profile ``ros2``, one schema
per message type (encoding ``ros2msg``: the type's ``.msg`` text followed by every type it uses,
each after a line of 80 ``=`` and ``MSG: <package>/<Type>``, rosbag2's complete message
definition), one channel per topic (encoding ``cdr``, metadata ``offered_qos_profiles``: the
profiles its writers offer, in rosbag2's YAML, so that ``ros2 bag play`` replays a latched
topic as transient-local), and every message as the serialized CDR bytes the subscription
took (nothing is decoded or re-encoded on the way).  ``ros2 bag
info|play FILE`` (Jazzy's default storage) and Foxglove open it.  The run's scene file rides
along as the attachment ``scene.yaml`` and the metadata record ``polymatch`` (what
``polymatch plot`` needs to draw the polytopes and compute the diameters of Theorems 4.1/4.2
from the poses).

The container is written by the ``mcap`` library (``mcap.writer.Writer``); this module only
says what goes in it.
"""

from __future__ import annotations

import importlib
import os
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, BinaryIO

from ...core.errors import PolymatchError
from .topics import QOS, TOPICS, full_name, message_type, profile

if TYPE_CHECKING:
    from mcap.writer import Writer
    from rclpy.qos import QoSProfile

DELIMITER = "=" * 80
SCENE_ATTACHMENT = "scene.yaml"
METADATA_NAME = "polymatch"
#: the reader's history per topic: a recorder that falls this far behind a writer loses messages
RECORDER_DEPTH = 1000
#: the channel metadata key of the writers' QoS profiles (rosbag2's MCAP storage)
OFFERED_QOS = "offered_qos_profiles"
#: RMW_DURATION_INFINITE in ns: what the ROS graph reports for a duration policy left unset
INFINITE_NS = 2**63 - 1


def type_name(cls: type) -> str:
    """The message class -> its ROS type name, e.g. ``std_msgs/msg/Float64``."""
    return f"{cls.__module__.split('.')[0]}/msg/{cls.__name__}"


def message_class(name: str) -> type:
    """``std_msgs/msg/Float64`` (or ``std_msgs/Float64``) -> the Python message class;
    PolymatchError (one line) for a type that is not installed."""
    package, _, rest = name.partition("/")
    cls_name = rest.rpartition("/")[2]
    try:
        cls = getattr(importlib.import_module(f"{package}.msg"), cls_name)
    except (ImportError, AttributeError, ValueError):
        raise PolymatchError(f"message type {name!r} is not installed") from None
    return cls  # type: ignore[no-any-return]


def share_directory(package: str) -> str:
    """The package's share directory: from the ament index (AMENT_PREFIX_PATH), else beside
    this interpreter (``<prefix>/share/<package>``, where the PyPI wheels put it)."""
    from ament_index_python.packages import get_package_share_directory

    try:
        return str(get_package_share_directory(package))
    except (LookupError, OSError, ValueError):
        pass
    for prefix in dict.fromkeys((sys.prefix, sys.base_prefix)):
        candidate = os.path.join(prefix, "share", package)
        if os.path.isdir(candidate):
            return candidate
    raise PolymatchError(f"no share directory of package {package!r} (AMENT_PREFIX_PATH)")


def _msg_text(package: str, name: str) -> str:
    path = os.path.join(share_directory(package), "msg", name + ".msg")
    try:
        with open(path, encoding="utf-8") as fh:
            return fh.read()
    except OSError as exc:
        raise PolymatchError(f"no message definition {path}: {exc.strerror}") from None


def _used_types(cls: type) -> list[tuple[str, str]]:
    """(package, Type) of every message type the fields of ``cls`` hold (arrays included),
    from the generated class's rosidl field types, sorted as rosbag2 sorts them."""
    used = set()
    for slot in getattr(cls, "SLOT_TYPES", ()):
        inner = getattr(slot, "value_type", slot)  # arrays and sequences: their element
        namespaces = getattr(inner, "namespaces", None)
        if namespaces:
            used.add((namespaces[0], inner.name))
    return sorted(used)


def message_definition(name: str) -> str:
    """The complete ``ros2msg`` definition of type ``name``, as rosbag2 stores it: the
    type's own ``.msg`` text, then each type it uses (depth first, each once) after the
    two-line delimiter ``====...`` / ``MSG: <package>/<Type>``."""
    seen: set[tuple[str, str]] = set()

    def text_of(package: str, type_: str) -> str:
        out = _msg_text(package, type_)
        for dep in _used_types(message_class(f"{package}/msg/{type_}")):
            if dep not in seen:
                seen.add(dep)
                out += f"\n{DELIMITER}\nMSG: {dep[0]}/{dep[1]}\n" + text_of(*dep)
        return out

    package, _, rest = name.partition("/")
    return text_of(package, rest.rpartition("/")[2])


@dataclass(frozen=True)
class RecordedTopic:
    """A topic to record: absolute name, type ('' = as its publishers offer), and the key of
    its writers' profile in ``topics.QOS`` ('' = adapted to its publishers)."""

    name: str
    type: str = ""
    qos: str = ""


def run_topics(ensemble: str, n_agents: int, dim: int, order: int,
               monitor: bool) -> list[RecordedTopic]:
    """What ``polymatch run --record`` records: every agent's pose (and twist, second order),
    /diagnostics and the status records; with the monitor, its diameters and markers."""
    keys = ["pose"] + (["twist"] if order == 2 else [])
    out = [RecordedTopic(full_name(ensemble, key, a), type_name(message_type(TOPICS[key].kind,
                                                                             dim)),
                         TOPICS[key].qos)
           for a in range(n_agents) for key in keys]
    shared = ["status", "diagnostics"]
    if monitor:
        shared += ["diameter", "diameter_centroid", "diameter_rotation", "markers", "certificate"]
    out += [RecordedTopic(full_name(ensemble, key), type_name(message_type(TOPICS[key].kind)),
                          TOPICS[key].qos) for key in shared]
    return out


def recorder_qos(key: str) -> QoSProfile:
    """A recorder's reader of a topic whose writers use ``QOS[key]``: their reliability and
    durability (so it matches them and takes a latched topic's last value), a deep history."""
    _, reliable, latched = QOS[key]
    return profile(RECORDER_DEPTH, reliable, latched)


def _duration(ns: int) -> dict[str, int]:
    sec, nsec = divmod(ns or INFINITE_NS, 10**9)
    return {"sec": sec, "nsec": nsec}


def offered_qos_profiles(profiles: Sequence[QoSProfile]) -> str:
    """The YAML list rosbag2 (metadata version 9, Jazzy) stores as a channel's
    ``offered_qos_profiles``: per writer its history, depth, reliability, durability (the
    policies by their ROS short keys), deadline, lifespan, liveliness and lease duration
    (``{sec, nsec}``; unset = infinite, as the graph reports it) and namespace conventions."""
    import yaml

    rows = [{
        "history": p.history.short_key,
        "depth": int(p.depth),
        "reliability": p.reliability.short_key,
        "durability": p.durability.short_key,
        "deadline": _duration(p.deadline.nanoseconds),
        "lifespan": _duration(p.lifespan.nanoseconds),
        "liveliness": p.liveliness.short_key,
        "liveliness_lease_duration": _duration(p.liveliness_lease_duration.nanoseconds),
        "avoid_ros_namespace_conventions": bool(p.avoid_ros_namespace_conventions),
    } for p in profiles]
    return yaml.safe_dump(rows, sort_keys=False, default_flow_style=False) if rows else ""


class RecordingWriter:
    """An MCAP file being written: a channel per topic, a schema per type, raw CDR messages.

    ``finish()`` writes the summary (message counts, indexes) and closes the file; a file not
    finished (its process killed) still holds every complete chunk but no summary.
    """

    stream: BinaryIO
    writer: Writer

    def __init__(self, path: str) -> None:
        from mcap.writer import LIBRARY_IDENTIFIER, Writer

        try:
            self.stream = open(path, "wb")  # noqa: SIM115 -- closed by finish()
        except OSError as exc:
            raise PolymatchError(f"{path}: {exc.strerror}") from None
        self.path = path
        self.writer = Writer(self.stream)
        self.writer.start(profile="ros2", library=f"polymatch_ros; {LIBRARY_IDENTIFIER}")
        self.schemas: dict[str, int] = {}
        self.counts: dict[int, int] = {}
        self.topics: dict[int, str] = {}
        self.finished = False

    def channel(self, topic: str, type_: str, offered: Sequence[QoSProfile] = ()) -> int:
        """Register ``topic`` of type ``type_`` (its schema once per type) whose writers offer
        the profiles ``offered``; the channel id."""
        if type_ not in self.schemas:
            self.schemas[type_] = self.writer.register_schema(
                name=type_, encoding="ros2msg", data=message_definition(type_).encode())
        channel = self.writer.register_channel(
            topic=topic, message_encoding="cdr", schema_id=self.schemas[type_],
            metadata={OFFERED_QOS: offered_qos_profiles(offered)})
        self.counts[channel], self.topics[channel] = 0, topic
        return channel

    def write(self, channel: int, data: bytes, log_time: int, publish_time: int) -> None:
        """One serialized message; times in ns since the epoch (received, sent)."""
        self.writer.add_message(channel_id=channel, log_time=log_time, data=data,
                                publish_time=publish_time, sequence=self.counts[channel])
        self.counts[channel] += 1

    def attach(self, name: str, data: bytes, media_type: str, log_time: int) -> None:
        self.writer.add_attachment(create_time=log_time, log_time=log_time, name=name,
                                   media_type=media_type, data=data)

    def metadata(self, values: Mapping[str, str]) -> None:
        self.writer.add_metadata(METADATA_NAME, dict(values))

    @property
    def messages(self) -> int:
        return sum(self.counts.values())

    def finish(self) -> None:
        """Write the summary and close the file (once)."""
        if self.finished:
            return
        self.finished = True
        try:
            self.writer.finish()
        finally:
            self.stream.close()

    def describe(self) -> str:
        """One line for people: how much went where."""
        heard = sum(1 for n in self.counts.values() if n)
        return (f"recorded {self.messages} messages on {heard} of {len(self.counts)} topics "
                f"to {self.path}")

