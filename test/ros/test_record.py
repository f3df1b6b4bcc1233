"""`polymatch run --record`: the MCAP file holds every step of every agent, read back by an
independent reader (rosbags: its own MCAP parser and CDR decoder, the types from the schemas
in the file), and equals what the run saved and reported; `polymatch plot` draws it.
"""

import math
import signal
from pathlib import Path

import numpy as np
import pytest
from core_testlib import triangles_yaml
from ros_harness import cli_argv, needs_ros

from polymatch_ros.cli import main
from polymatch_ros.core.metrics import ensemble_metrics
from polymatch_ros.core.saved import load_saved
from polymatch_ros.core.scenes.scene import load_scene
from polymatch_ros.ros.wire import run_records

pytestmark = needs_ros

# three triangles, first order, ten lockstep steps
SCENE = triangles_yaml("three_triangles", seed=5, count=3, method="lie_euler", dt=0.05, t_end=0.5,
                       snapshots=[0, 0.25, 0.5])
STEPS = 10
TYPES = {
    "/polymatch/agent_0/pose": "geometry_msgs/msg/PoseStamped",
    "/polymatch/agent_1/pose": "geometry_msgs/msg/PoseStamped",
    "/polymatch/agent_2/pose": "geometry_msgs/msg/PoseStamped",
    "/polymatch/diameter": "std_msgs/msg/Float64",
    "/polymatch/diameter/centroid": "std_msgs/msg/Float64",
    "/polymatch/diameter/rotation": "std_msgs/msg/Float64",
    "/polymatch/markers": "visualization_msgs/msg/MarkerArray",
    "/polymatch/certificate": "diagnostic_msgs/msg/DiagnosticStatus",
    "/polymatch/status": "polymatch_interfaces/msg/RunRecord",
    "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray",
}


def read_with_rosbags(path):
    """{topic: (type, [(log time, message)])} as rosbags reads and decodes the file."""
    from rosbags.highlevel import AnyReader

    out = {}
    with AnyReader([Path(path)]) as reader:
        for c in reader.connections:
            out[c.topic] = (c.msgtype, [])
        for c, stamp, raw in reader.messages():
            out[c.topic][1].append((stamp, reader.deserialize(raw, c.msgtype)))
    return out


def offered(path):
    """{topic: [(reliability, durability) of each writer]} of the channels' offered QoS
    profiles, as rosbags parses them."""
    from rosbags.highlevel import AnyReader

    with AnyReader([Path(path)]) as reader:
        return {c.topic: [(q.reliability.name, q.durability.name)
                          for q in c.ext.offered_qos_profiles] for c in reader.connections}


def planar(msg):
    """A PoseStamped -> (t, centroid, rotation matrix), computed here from the quaternion."""
    q, p = msg.pose.orientation, msg.pose.position
    angle = 2.0 * math.atan2(q.z, q.w)
    rot = np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])
    return msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec, np.array([p.x, p.y]), rot


def test_run_record_holds_every_step_and_equals_the_runs_results(ros, tmp_path):
    scene_file, mcap = tmp_path / "three.yaml", tmp_path / "run.mcap"
    saved, records = tmp_path / "final.npz", tmp_path / "records.jsonl"
    scene_file.write_text(SCENE)
    # beside the run, in its domain: `polymatch record`, types and QoS from the graph
    other = tmp_path / "other.mcap"
    standalone = ros.start(cli_argv("record", "/polymatch/diameter", "/polymatch/status",
                                    "/clock", "-o", other), timeout=150)
    # one agent process (-k 3): the runner, the monitor, the recorder and it
    proc = ros.start(cli_argv("run", scene_file, "-k", 3, "--record", mcap, "--save", saved,
                              "--run-records", records, "--no-compare", "--timeout", 120),
                     timeout=150)
    rc = ros.wait(proc, 160)
    out = ros.output(proc)
    assert rc == 3, out  # ran to t_end without matching (t_end is short)
    scene = load_scene(str(scene_file))
    recs = run_records(records.read_text().splitlines())
    (mon,) = [r for r in recs if r.role == "monitor"]
    assert [(r.agents, r.steps) for r in recs if r.role == "agent"] == [((0, 1, 2), STEPS)]

    got = read_with_rosbags(mcap)
    assert {t: v[0] for t, v in got.items()} == TYPES
    # what the writers offer (the topic table's profiles): latched headline values and records,
    # volatile poses and diagnostics, so a player replays each as it was published
    profiles = offered(mcap)
    latched = ("/polymatch/diameter", "/polymatch/diameter/centroid",
               "/polymatch/diameter/rotation", "/polymatch/certificate", "/polymatch/status")
    for topic in TYPES:
        durability = "TRANSIENT_LOCAL" if topic in latched else "VOLATILE"
        assert profiles[topic] == [("RELIABLE", durability)], topic
    total = sum(len(v[1]) for v in got.values())
    assert f"recorded {total} messages on {len(TYPES)} of {len(TYPES)} topics to {mcap}" in out
    final = load_saved(saved).groups[0]
    for a in range(3):
        poses = [planar(m) for _, m in got[f"/polymatch/agent_{a}/pose"][1]]
        # every step, once, in order: t = 0, dt, ..., t_end
        assert len(poses) == STEPS + 1
        np.testing.assert_allclose([p[0] for p in poses], np.arange(STEPS + 1) * 0.05,
                                   atol=1e-9)
        x0 = scene.initial.groups[0].x[a] + scene.origin
        np.testing.assert_array_equal(poses[0][1], x0)
        np.testing.assert_array_equal(poses[-1][1], final.centroids[-1][a])
        np.testing.assert_allclose(poses[-1][2], final.rotations[-1][a], atol=1e-12)
    # the monitor's reports (at most report_rate a second): the last is the final step's
    diameters = [m.data for _, m in got["/polymatch/diameter"][1]]
    assert 1 <= len(diameters) <= mon.reports and diameters[-1] == mon.diameter
    assert any(m.role == "monitor" and m.run_id == mon.run_id
               for _, m in got["/polymatch/status"][1])

    from polymatch_ros.ros.wire.recording_read import diameter_series, read_recording

    series = diameter_series(read_recording(str(mcap)))
    assert series.source == "poses" and len(series.t) == STEPS + 1
    initial = ensemble_metrics(scene.model, scene.initial).diameter
    assert series.matching[0] == pytest.approx(initial, rel=1e-12)
    assert series.matching[-1] == pytest.approx(mon.diameter, rel=1e-12)
    png = tmp_path / "run.png"
    assert main(["plot", str(mcap), "--figure", str(png)]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    # SIGTERM ends `polymatch record` normally: the file is finished (rosbags reads it)
    ros.kill(standalone, signal.SIGTERM)
    assert ros.wait(standalone, 30) == 0, ros.output(standalone)
    beside = read_with_rosbags(other)
    assert beside["/polymatch/diameter"][0] == "std_msgs/msg/Float64"
    # found in the graph: the profile its one writer (the monitor) offers
    assert offered(other)["/polymatch/diameter"] == [("RELIABLE", "TRANSIENT_LOCAL")]
    assert offered(other)["/clock"] == [("BEST_EFFORT", "VOLATILE")]  # lockstep's /clock
    assert beside["/clock"][0] == "rosgraph_msgs/msg/Clock"
    ticks = [m.clock.sec * 10**9 + m.clock.nanosec for _, m in beside["/clock"][1]]
    # the recorder, found late by a run of ten steps, may hear none of its few /clock samples
    # (best effort); those it heard go forward
    assert all(a < b for a, b in zip(ticks, ticks[1:])), ticks
    assert beside["/polymatch/diameter"][1][-1][1].data == mon.diameter  # latched: the last
    statuses = [m for _, m in beside["/polymatch/status"][1]]  # decoded by rosbags
    # the monitor's last report, as the run's --run-records has it
    assert any(m.role == "monitor" and (m.t, m.diameter) == (mon.t, mon.diameter)
               for m in statuses), statuses
