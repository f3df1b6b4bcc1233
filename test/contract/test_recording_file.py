"""Recordings without a ROS process: the MCAP file's schemas, and what `polymatch plot` reads.

The schemas (``ros2msg``: rosbag2's complete definition) are parsed by an independent library
(rosbags) and compared with the generated message classes; a file written here from known
states (serialized by rclpy, written by ``RecordingWriter``) is read back by rosbags (counts,
types) and by ``recording_read`` (states and diameters equal to ``core.metrics`` of the
states written).
"""

import math
import re
from pathlib import Path

import numpy as np
import pytest
from core_testlib import triangles_yaml
from ros_harness import needs_ros

from polymatch_ros.cli import main
from polymatch_ros.core.metrics import ensemble_metrics
from polymatch_ros.core.model import GroupState, State
from polymatch_ros.core.scenes.scene import load_scene

pytestmark = needs_ros

# one snapshot: `plot --figure` draws it above the diameters (each more costs a drawing)
SCENE = triangles_yaml("three_triangles", seed=3, count=3, method="lie_euler", dt=0.1, t_end=0.3,
                       snapshots=[0.2])
DT = 0.1


def fields_of(cls):
    return list(cls.get_fields_and_field_types())


def used_types(name):
    """``name`` and every message type its fields hold, from the generated classes' field type
    strings ('std_msgs/Header', 'sequence<visualization_msgs/Marker>', ...)."""
    from polymatch_ros.ros.wire.recording import message_class

    found, todo = set(), [name]
    while todo:
        current = todo.pop()
        if current in found:
            continue
        found.add(current)
        for text in message_class(current).get_fields_and_field_types().values():
            todo += [f"{p}/msg/{t}" for p, t in re.findall(r"([a-z0-9_]+)/([A-Za-z0-9]+)", text)]
    return found


@pytest.mark.parametrize("dim,order", [(2, 2), (4, 2)])
def test_every_recorded_type_has_a_definition_rosbags_parses_to_the_classes_fields(dim, order):
    from rosbags.typesys import get_types_from_msg

    from polymatch_ros.ros.wire.recording import message_class, message_definition, run_topics

    types = {t.type for t in run_topics("polymatch", 2, dim, order, monitor=True)}
    assert len(types) >= 5
    for name in types:
        parsed = get_types_from_msg(message_definition(name), name)
        assert set(parsed) == used_types(name)  # complete: every type it holds, each once
        for type_name, (_, fields) in parsed.items():  # the type and every type it holds
            assert [f[0] for f in fields] == fields_of(message_class(type_name)), type_name


def moved(scene, k):
    """The scene's initial state contracted towards the origin and turned, step k."""
    (gs,) = scene.initial.groups
    x = gs.x * (1.0 - 0.25 * k)
    rot = gs.rot * (1.0 - 0.3 * k) + 0.05 * k  # planar angles
    return State(k * DT, (GroupState(x, rot),))


def write_recording(path, scene, states, skip=()):
    """Each agent's pose at each state's time (but the (agent, step) pairs in ``skip``), and
    one string message, with the scene attached; returns the number of pose messages."""
    from rclpy.serialization import serialize_message
    from std_msgs.msg import String

    from polymatch_ros.ros import wire
    from polymatch_ros.ros.wire.recording import SCENE_ATTACHMENT, RecordingWriter, type_name

    grp, n = scene.model.rotations, scene.model.n_agents
    out = RecordingWriter(str(path))
    out.attach(SCENE_ATTACHMENT, SCENE.encode(), "application/yaml", 1)
    channels = [out.channel(f"/polymatch/agent_{a}/pose", "geometry_msgs/msg/PoseStamped")
                for a in range(n)]
    note = out.channel("/polymatch/status", type_name(String))
    written = 0
    for k, st in enumerate(states):
        (gs,) = st.groups
        for a in range(n):
            if (a, k) in skip:
                continue
            msg = wire.pose_message(grp, st.t, gs.x[a] + scene.origin, grp.take(gs.rot, [a]),
                                    "world")
            out.write(channels[a], serialize_message(msg), 10**9 + k, 10**9 + k)
            written += 1
    out.write(note, serialize_message(String(data="{}")), 2 * 10**9, 2 * 10**9)
    out.finish()
    return written


def test_a_recording_reads_back_as_the_states_written_and_their_diameters(tmp_path):
    from rosbags.highlevel import AnyReader

    from polymatch_ros.ros.wire.recording_read import diameter_series, read_recording, states_at

    scene = load_scene(SCENE)
    states = [moved(scene, k) for k in range(4)]
    path = tmp_path / "run.mcap"
    # agent 2 misses step 1: the state there holds its pose of step 0
    count = write_recording(path, scene, states, skip={(2, 1)})
    with AnyReader([path]) as reader:  # an independent reader: its own parser and decoder
        counts = {c.topic: (c.msgtype, c.msgcount) for c in reader.connections}
    assert counts["/polymatch/agent_2/pose"] == ("geometry_msgs/msg/PoseStamped", 3)
    assert counts["/polymatch/status"] == ("std_msgs/msg/String", 1)
    assert sum(c for t, (_, c) in counts.items() if t.endswith("pose")) == count == 11

    rec = read_recording(str(path))
    assert rec.scene is not None and rec.scene.model.n_agents == 3
    series = diameter_series(rec)
    assert series.source == "poses"
    held = State(DT, (GroupState(
        np.vstack([states[1].groups[0].x[:2], states[0].groups[0].x[2:]]),
        np.concatenate([states[1].groups[0].rot[:2], states[0].groups[0].rot[2:]])),))
    want = [ensemble_metrics(scene.model, st) for st in [states[0], held, *states[2:]]]
    np.testing.assert_allclose(series.t, [0.0, 0.1, 0.2, 0.3], atol=1e-12)
    np.testing.assert_allclose(series.matching, [m.diameter for m in want], rtol=1e-12)
    np.testing.assert_allclose(series.centroid, [m.groups[0].centroid_diameter for m in want],
                               rtol=1e-12)
    np.testing.assert_allclose(series.rotation, [m.groups[0].rotation_diameter for m in want],
                               rtol=1e-12)
    # at t = 0.25 the last step at or before it: t = 0.2
    (at,) = states_at(rec, [0.25])
    assert at.t == pytest.approx(0.2)
    np.testing.assert_allclose(at.groups[0].x, states[2].groups[0].x, atol=1e-12)


def test_without_the_scene_the_diameters_are_the_monitors_reports(tmp_path):
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
    from rclpy.serialization import serialize_message

    from polymatch_ros.ros.wire.recording import RecordingWriter
    from polymatch_ros.ros.wire.recording_read import diameter_series, read_recording

    path = tmp_path / "diag.mcap"
    out = RecordingWriter(str(path))
    channel = out.channel("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray")
    for k, (t, d, c, r) in enumerate([(0.5, 4.0, 3.0, 2.0), (1.0, 1.0, 0.5, 0.25)]):
        top = DiagnosticStatus(values=[KeyValue(key="t", value=repr(t)),
                                       KeyValue(key="diameter", value=repr(d)),
                                       KeyValue(key="agents_heard", value="3")])
        groups = [DiagnosticStatus(values=[KeyValue(key="centroid_diameter", value=repr(v)),
                                           KeyValue(key="rotation_diameter", value=repr(w))])
                  for v, w in ((c, r / 2), (c / 2, r))]
        agent = DiagnosticStatus(values=[KeyValue(key="t", value="9.0")])  # an agent's: skipped
        for statuses in ([top, *groups], [agent]):
            out.write(channel, serialize_message(DiagnosticArray(status=statuses)), k, k)
    out.finish()
    series = diameter_series(read_recording(str(path)))
    assert series.source == "diagnostics"
    assert series.t.tolist() == [0.5, 1.0]
    assert series.matching.tolist() == [4.0, 1.0]
    assert series.centroid.tolist() == [3.0, 0.5]
    assert series.rotation.tolist() == [2.0, 0.25]


def test_plot_prints_a_table_or_draws_a_png(tmp_path, capsys):
    scene = load_scene(SCENE)
    path = tmp_path / "run.mcap"
    write_recording(path, scene, [moved(scene, k) for k in range(4)])
    assert main(["plot", str(path), "--at", "0,0.3"]) == 0
    text = capsys.readouterr().out
    first = ensemble_metrics(scene.model, scene.initial).diameter
    assert "/polymatch/agent_1/pose" in text and f"{first:.3e}" in text
    assert main(["plot", str(path), "--figure", str(tmp_path / "run")]) == 0
    png = tmp_path / "run.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    import matplotlib.image

    height, width = matplotlib.image.imread(png).shape[:2]
    assert width > 600 and height > 600  # snapshots above the diameters


@pytest.mark.parametrize("args,message", [
    (["plot", "{missing}"], "No such file"),
    (["plot", "{text}"], "not a readable MCAP file"),
    (["plot", "{text}", "--at", "1,x"], "expected times like"),
    (["record", "relative/topic", "-o", "{out}"], "must be an absolute name"),
    (["record", "/a", "-o", "{missing}/x.mcap"], "does not exist"),
])
def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys, args, message):
    text = tmp_path / "notes.mcap"
    text.write_text("not an mcap file\n")
    paths = {"missing": tmp_path / "missing", "text": text, "out": tmp_path / "o.mcap"}
    try:
        code = main([a.format(**paths) for a in args])
    except SystemExit as exc:  # argparse's own errors
        code = exc.code
    assert code == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1, err


def test_read_recording_of_an_unfinished_file_says_so(tmp_path):
    from polymatch_ros.core.errors import ParameterError
    from polymatch_ros.ros.wire.recording import RecordingWriter
    from polymatch_ros.ros.wire.recording_read import read_recording

    path = tmp_path / "cut.mcap"
    out = RecordingWriter(str(path))
    out.channel("/polymatch/diameter", "std_msgs/msg/Float64")
    out.stream.flush()  # never finished: no summary (a recorder killed by SIGKILL)
    with pytest.raises(ParameterError, match="not finished|not a readable"):
        read_recording(str(path))
    out.finish()
    assert Path(path).stat().st_size > 0


# -- the run's own messages (polymatch_interfaces) and the writers' QoS, as rosbag2 keeps them --

INTERFACES = Path(__file__).resolve().parents[2] / "polymatch_interfaces" / "msg"
INFINITE = {"sec": 9223372036, "nsec": 854775807}  # RMW_DURATION_INFINITE


def msg_file_typestore():
    """Jazzy's standard types plus every polymatch_interfaces type, parsed by rosbags from the
    repository's .msg files (not from anything the package writes)."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    types = {}
    for path in sorted(INTERFACES.glob("*.msg")):
        types.update(get_types_from_msg(path.read_text(), f"polymatch_interfaces/msg/{path.stem}"))
    store.register(types)
    return store, sorted(types)


def interface_messages():
    """(topic, type, QOS key, message, the fields expected after decoding) of messages of the
    interface package, with values chosen here."""
    from builtin_interfaces.msg import Time
    from std_msgs.msg import Header

    from polymatch_interfaces.msg import AgentState, ControlCommand, NamedValue, RunRecord

    # second order: every float64 sequence holds numbers (rclpy's serialize_message pads an
    # empty float64[] in its buffer, which DDS does not send and rosbags rejects as too long)
    state = AgentState(header=Header(stamp=Time(sec=1, nanosec=250_000_000), frame_id="world"),
                       run_id=2**40 + 7, agent=3, centroid=[1.5, -2.0],
                       rotation=[0.0, -1.0, 1.0, 0.0], velocity=[0.5, 0.25],
                       angular_velocity=[0.0, -0.125, 0.125, 0.0])
    record = RunRecord(role="monitor", mode="lockstep", t=0.75, agents=[0, 1, 2], finished=True,
                       ms_per_round=[NamedValue(name="publish", value=0.125)],
                       diameter=float("nan"), n_agents=3, resumed_at=-1)
    command = ControlCommand(command=ControlCommand.PAUSE, epoch=Time(sec=1_700_000_000))
    return [
        ("/polymatch/agent_3/state", "polymatch_interfaces/msg/AgentState", "pose", state,
         {"run_id": 2**40 + 7, "agent": 3, "centroid": [1.5, -2.0],
          "rotation": [0.0, -1.0, 1.0, 0.0], "velocity": [0.5, 0.25],
          "angular_velocity": [0.0, -0.125, 0.125, 0.0]}),
        ("/polymatch/status", "polymatch_interfaces/msg/RunRecord", "status", record,
         {"role": "monitor", "mode": "lockstep", "t": 0.75, "agents": [0, 1, 2],
          "finished": True, "n_agents": 3, "resumed_at": -1}),
        ("/polymatch/control", "polymatch_interfaces/msg/ControlCommand", "control", command,
         {"command": 2}),
    ]


def test_interface_messages_and_offered_qos_read_back_with_rosbags(tmp_path):
    """A player needs the writers' profiles (rosbag2's offered_qos_profiles) to replay a latched
    topic as transient-local, and a reader without the package needs the complete schemas:
    rosbags reads both; the messages decode, with the types of the .msg files, to the values
    written, and the embedded schemas define the same types as the .msg files."""
    from rclpy.serialization import serialize_message
    from rosbags.highlevel import AnyReader
    from rosbags.interfaces import QosDurability, QosHistory, QosReliability

    from polymatch_ros.ros.wire.recording import RecordingWriter
    from polymatch_ros.ros.wire.topics import qos_profiles

    cases = interface_messages()
    path = tmp_path / "typed.mcap"
    out = RecordingWriter(str(path))
    for topic, type_, key, msg, _ in cases:
        channel = out.channel(topic, type_, [qos_profiles()[key]])
        out.write(channel, serialize_message(msg), 5, 5)
    out.finish()

    store, names = msg_file_typestore()
    # the writers' profiles, as topics.QOS states them in prose: (history depth, reliable, latched)
    want = {"/polymatch/agent_3/state": (100, QosReliability.RELIABLE, QosDurability.VOLATILE),
            "/polymatch/status": (1, QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL),
            "/polymatch/control": (10, QosReliability.RELIABLE, QosDurability.VOLATILE)}
    with AnyReader([path]) as reader:
        for c in reader.connections:
            (qos,) = c.ext.offered_qos_profiles
            assert (qos.depth, qos.reliability, qos.durability) == want[c.topic], c.topic
            assert qos.history == QosHistory.KEEP_LAST
            assert tuple(qos.deadline) == tuple(INFINITE.values())
        embedded = reader.typestore.fielddefs
        for name in names:
            if name in embedded:
                assert embedded[name] == store.fielddefs[name], name
        assert {t for _, t, *_ in cases} <= set(embedded)
        decoded = {c.topic: store.deserialize_cdr(raw, c.msgtype)
                   for c, _, raw in reader.messages()}
    for topic, _, _, _, fields in cases:
        for name, value in fields.items():
            got = getattr(decoded[topic], name)
            assert (got.tolist() if hasattr(got, "tolist") else got) == value, (topic, name)
    assert decoded["/polymatch/agent_3/state"].header.stamp.nanosec == 250_000_000
    assert decoded["/polymatch/status"].ms_per_round[0].value == 0.125
    assert math.isnan(decoded["/polymatch/status"].diameter)


def test_offered_qos_profiles_are_rosbag2s_yaml():
    """The metadata text, parsed as YAML, has rosbag2's (version 9) layout: one mapping per
    writer, the policies by name, durations as {sec, nsec}; a reference written here."""
    import yaml
    from rclpy.duration import Duration
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    from polymatch_ros.ros.wire.recording import offered_qos_profiles

    latched = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
    lossy = QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT,
                       lifespan=Duration(seconds=2, nanoseconds=500))
    assert yaml.safe_load(offered_qos_profiles([latched, lossy])) == [
        {"history": "keep_last", "depth": 1, "reliability": "reliable",
         "durability": "transient_local", "deadline": INFINITE, "lifespan": INFINITE,
         "liveliness": "system_default", "liveliness_lease_duration": INFINITE,
         "avoid_ros_namespace_conventions": False},
        {"history": "keep_last", "depth": 5, "reliability": "best_effort",
         "durability": "volatile", "deadline": INFINITE, "lifespan": {"sec": 2, "nsec": 500},
         "liveliness": "system_default", "liveliness_lease_duration": INFINITE,
         "avoid_ros_namespace_conventions": False},
    ]
    assert offered_qos_profiles([]) == ""
