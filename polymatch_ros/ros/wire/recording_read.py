"""A recording read back (``polymatch plot``): what it holds, the diameters against simulated
time, and the ensemble's state at chosen times.

The file is read with the ``mcap`` library and its messages decoded from the schemas they
carry (``mcap_ros2``), so no ROS installation is needed.  With the scene (the attachment
``scene.yaml`` of ``polymatch run --record``, or ``polymatch record --scene``) every step's
poses (stamped with simulated time) become the ensemble's state, held per agent at its latest
pose, and the diameters are computed from it (``core.metrics``: the matching diameter of
Theorems 4.1/4.2, the centroid diameter of Prop. 2.1, the rotation diameter of Prop. 2.2);
without it they are the monitor's reports on /diagnostics.
"""

from __future__ import annotations

import re
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from ...core.errors import ParameterError
from ...core.metrics import ensemble_metrics
from ...core.model import State
from .assembly import Row, state_of
from .motion import Received, decode_pose_msg
from .recording import METADATA_NAME, SCENE_ATTACHMENT

if TYPE_CHECKING:
    from ...core.scenes.scene import Scene

POSE_TOPIC = re.compile(r"/agent_(\d+)/pose$")
#: at most this many states are evaluated for the diameter curves (evenly spaced in steps)
MAX_POINTS = 2000


@dataclass(frozen=True)
class TopicCount:
    """One recorded topic: its name, type and number of messages."""

    topic: str
    type: str
    messages: int


@dataclass(frozen=True)
class Series:
    """Diameters against simulated time ``t`` (max over groups); ``source``: 'poses' (computed
    from the recorded poses and the scene) or 'diagnostics' (the monitor's reports)."""

    t: np.ndarray
    matching: np.ndarray
    centroid: np.ndarray
    rotation: np.ndarray
    source: str


@dataclass
class Recording:
    """What ``read_recording`` found: topics, the scene (None: not attached), each agent's
    decoded poses in the order received, and the monitor's reports (t, matching, centroid,
    rotation diameters)."""

    path: str
    topics: list[TopicCount]
    duration: float                    # seconds between the first and the last message
    scene: Scene | None
    poses: dict[int, list[Received]] = field(default_factory=dict)
    reports: list[tuple[float, float, float, float]] = field(default_factory=list)


def _open(path: str) -> Any:
    try:
        return open(path, "rb")  # noqa: SIM115 -- closed by the caller
    except OSError as exc:
        raise ParameterError(f"{path}: {exc.strerror}") from None


def read_recording(path: str) -> Recording:
    """Read the MCAP file ``path``; ParameterError (one line) if it is no finished recording."""
    from mcap.exceptions import McapError
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    with _open(path) as stream:
        try:
            reader = make_reader(stream, decoder_factories=[DecoderFactory()])
            summary = reader.get_summary()
            if summary is None or summary.statistics is None:
                raise ParameterError(f"{path}: no MCAP summary (a recording not finished)")
            rec = Recording(path, _topics(summary), _duration(summary.statistics),
                            _scene(reader))
            _read_messages(reader, rec)
        except (McapError, ValueError, EOFError) as exc:
            raise ParameterError(f"{path}: not a readable MCAP file ({exc})") from None
    return rec


def _topics(summary: Any) -> list[TopicCount]:
    counts = summary.statistics.channel_message_counts
    out = []
    for cid, ch in sorted(summary.channels.items()):
        schema = summary.schemas.get(ch.schema_id)
        out.append(TopicCount(ch.topic, schema.name if schema else "", counts.get(cid, 0)))
    return out


def _duration(stats: Any) -> float:
    return max(0, stats.message_end_time - stats.message_start_time) * 1e-9 \
        if stats.message_count else 0.0


def _scene(reader: Any) -> Scene | None:
    """The attached scene (with the run's t_end), or None."""
    from ...core.scenes.scene import load_scene

    text = next((a.data.decode() for a in reader.iter_attachments()
                 if a.name == SCENE_ATTACHMENT), None)
    if text is None:
        return None
    meta: dict[str, str] = next(
        (m.metadata for m in reader.iter_metadata() if m.name == METADATA_NAME), {})
    t_end = float(meta.get("t_end", "0") or 0)
    return load_scene(text + "\n", {"time.t_end": t_end} if t_end > 0 else None)


def _read_messages(reader: Any, rec: Recording) -> None:
    """Decode the poses (with a scene) and /diagnostics; nothing else is decoded."""
    wanted = {t.topic: POSE_TOPIC.search(t.topic) for t in rec.topics}
    topics = [t for t, m in wanted.items() if t == "/diagnostics" or (m and rec.scene)]
    scene = rec.scene
    for _, channel, _, msg in reader.iter_decoded_messages(topics=topics):
        if channel.topic == "/diagnostics":
            report = _monitor_report(msg)
            if report is not None:
                rec.reports.append(report)
            continue
        assert scene is not None  # pose topics are decoded only with the scene
        agent = int(wanted[channel.topic].group(1))  # type: ignore[union-attr]
        if agent < scene.model.n_agents:
            got, _ = decode_pose_msg(msg, scene.model.rotations, scene.dim)
            if got is not None:
                rec.poses.setdefault(agent, []).append(got)


def _monitor_report(msg: Any) -> tuple[float, float, float, float] | None:
    """The monitor's DiagnosticArray (its first status holds t, diameter, agents_heard; one
    status per group follows) -> (t, matching, centroid, rotation), else None (an agent's)."""
    statuses = list(msg.status)
    if not statuses:
        return None
    top = {kv.key: kv.value for kv in statuses[0].values}
    if "agents_heard" not in top or "t" not in top:
        return None
    groups = [{kv.key: kv.value for kv in s.values} for s in statuses[1:]]
    try:
        centroid = max(float(g["centroid_diameter"]) for g in groups)
        rotation = max(float(g["rotation_diameter"]) for g in groups)
        return float(top["t"]), float(top["diameter"]), centroid, rotation
    except (KeyError, ValueError):
        return None


def _keys(rec: Recording) -> list[int]:
    """The pose stamps (ns) from the first at which every agent has been heard."""
    if rec.scene is None or len(rec.poses) < rec.scene.model.n_agents:
        return []
    first = max(min(p.key for p in poses) for poses in rec.poses.values())
    return sorted({p.key for poses in rec.poses.values() for p in poses if p.key >= first})


def _state(scene: Scene, latest: dict[int, Received], key: int) -> State:
    rows = {a: Row(latest[a].vec - scene.origin, latest[a].rot)
            for a in range(scene.model.n_agents)}
    return state_of(scene.model, rows, key * 1e-9)


def states(rec: Recording, keys: Sequence[int]) -> Iterator[State]:
    """The ensemble's state at each stamp of ``keys`` (ascending): every agent at its latest
    pose stamped at or before it (lockstep: all at that step)."""
    assert rec.scene is not None  # poses are read only with a scene
    stream = sorted(((p.key, a, p) for a, poses in rec.poses.items() for p in poses),
                    key=lambda item: (item[0], item[1]))
    latest: dict[int, Received] = {}
    k = 0
    for key in keys:
        while k < len(stream) and stream[k][0] <= key:
            latest[stream[k][1]] = stream[k][2]
            k += 1
        yield _state(rec.scene, latest, key)


def diameter_series(rec: Recording, max_points: int = MAX_POINTS) -> Series:
    """The diameters against simulated time: from the poses (with the scene), else from the
    monitor's reports; ParameterError if the recording holds neither."""
    keys = _keys(rec)
    if keys and rec.scene is not None:
        if len(keys) > max_points:
            keys = [keys[i] for i in np.unique(np.linspace(0, len(keys) - 1, max_points)
                                                 .round().astype(int))]
        rows = []
        for st in states(rec, keys):
            met = ensemble_metrics(rec.scene.model, st)
            rows.append((st.t, met.diameter, max(g.centroid_diameter for g in met.groups),
                         max(g.rotation_diameter for g in met.groups)))
        source = "poses"
    elif rec.reports:
        rows, source = sorted(rec.reports), "diagnostics"
    else:
        raise ParameterError(f"{rec.path}: neither every agent's poses with the scene nor the "
                             f"monitor's /diagnostics: no diameters to show")
    t, matching, centroid, rotation = (np.array(c) for c in zip(*rows))
    return Series(t, matching, centroid, rotation, source)


def states_at(rec: Recording, times: Sequence[float]) -> list[State]:
    """The state at (the last step at or before) each of ``times``; [] without the scene."""
    keys = _keys(rec)
    if not keys:
        return []
    have = np.array(keys)
    picks = [keys[max(0, int(np.searchsorted(have, round(t * 1e9), side="right")) - 1)]
             for t in times]
    order = sorted(range(len(picks)), key=picks.__getitem__)
    found = list(states(rec, [picks[i] for i in order]))
    out: list[State] = [found[0]] * len(picks)
    for position, i in enumerate(order):
        out[i] = found[position]
    return out
