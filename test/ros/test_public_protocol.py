"""The protocol is public: another implementation joins a run, and nothing else does.

- an agent written from the ``.msg`` files and the ROS interface guide alone
  (``test/support/foreign_agent.py``: rclpy, numpy, scipy and ``polymatch_interfaces``, nothing of
  ``polymatch_ros``) runs as agent 7 beside seven of the package's realtime agents and the
  monitor, and the ensemble matches (Theorem 4.2): checked by brute force on the saved final
  states, and agent 7's saved state is the one the foreign agent computed;
- a writer of another type on an agent's state topic is never matched (DDS type matching), while
  a writer of the run's own type is.
"""

import ast
import os
import re
import textwrap

import numpy as np
from ros_harness import PY, REPO, cli_argv, needs_ros, scene_path

from polymatch_ros.core.saved import load_saved

pytestmark = needs_ros

FOREIGN = os.path.join(REPO, "test", "support", "foreign_agent.py")
RUN_ID = 4242
AGENT = 7
SCENE = "congruent_triangles"


def test_an_agent_written_from_the_msg_files_joins_and_the_ensemble_matches_theorem_4_2(
        ros, tmp_path):
    out = tmp_path / "final.npz"
    foreign = ros.start([PY, FOREIGN, scene_path(SCENE), str(AGENT), str(RUN_ID), "150"],
                        timeout=160, name="foreign_agent")
    proc = ros.start(cli_argv("run", scene_path(SCENE), "--mode", "realtime", "--only", "0-6",
                              "--run-id", RUN_ID, "--rate", 20, "--time-scale", 4,
                              "--timeout", 140, "--save", out), timeout=150)
    rc = ros.wait(proc, 160)
    text = ros.output(proc)
    assert rc == 0 and "converged" in text, text[-3000:]
    ros.wait(foreign, 40)
    said = re.search(r"^foreign agent 7: final t = (\S+), x = (\[.*?\]), dropped (\d+)$",
                     ros.output(foreign), re.M)
    assert said, ros.output(foreign)
    data = load_saved(out).groups[0]
    x, rot = data.centroids[-1], data.rotations[-1]
    assert x.shape == (8, 2) and rot.shape == (8, 2, 2)
    # brute force over every pair: centroids together, rotations equal (Theorem 4.2)
    pairs = [(i, j) for i in range(8) for j in range(i + 1, 8)]
    assert max(np.linalg.norm(x[i] - x[j]) for i, j in pairs) < 1e-3
    assert max(np.linalg.norm(rot[i] - rot[j]) for i, j in pairs) < 1e-3
    for r in rot:  # saved in SO(2)
        assert abs(np.linalg.det(r) - 1) < 1e-9 and np.allclose(r.T @ r, np.eye(2), atol=1e-9)
    # agent 7's saved state is the foreign agent's own (relative to the scene's origin there)
    from polymatch_ros.core.scenes.scene import load_scene

    origin = load_scene(scene_path(SCENE)).origin
    assert np.allclose(x[AGENT] - origin, ast.literal_eval(said.group(2)), atol=1e-9)


# The reader listens this long once it sees the wrong writer in the ROS graph (DDS discovery
# gives the graph and a match of the same type alike); the wrong writer, discovered within about
# a second of its start, writes a little longer
LISTEN = 3.0
WRONG_WRITES = LISTEN + 3.0

READER = textwrap.dedent(f"""
    import time, rclpy
    from polymatch_ros.ros import wire
    rclpy.init()
    reader = rclpy.create_node("reader", namespace="/polymatch")
    heard, most, topic = [], 0, "/polymatch/agent_3/state"
    sub = wire.subscription(reader, "state", heard.append, 2, 3)
    print("READING", flush=True)
    end = time.monotonic() + 30.0
    while time.monotonic() < end and reader.count_publishers(topic) == 0:
        rclpy.spin_once(reader, timeout_sec=0.05)
    seen = reader.count_publishers(topic)
    end = time.monotonic() + {LISTEN}
    while time.monotonic() < end:
        rclpy.spin_once(reader, timeout_sec=0.05)
        most = max(most, sub.get_publisher_count())
    print("WRONG", seen, most, len(heard), flush=True)
    end, most = time.monotonic() + 30.0, 0
    while time.monotonic() < end and not heard:
        rclpy.spin_once(reader, timeout_sec=0.05)
        most = max(most, sub.get_publisher_count())
    end = time.monotonic() + 1.0  # matched a while more: the writer sees it too
    while time.monotonic() < end:
        rclpy.spin_once(reader, timeout_sec=0.05)
        most = max(most, sub.get_publisher_count())
    print("RIGHT", most, len(heard) > 0, flush=True)
    reader.destroy_node()
    rclpy.shutdown()
""")

# argv[2] seconds: the wrong writer writes that long, the typed one that long once it has matched
# the reader (at most 30 s)
WRITER = textwrap.dedent("""
    import sys, time, rclpy
    from std_msgs.msg import Float64MultiArray
    from polymatch_interfaces.msg import AgentState
    rclpy.init()
    node = rclpy.create_node("writer")
    typed = sys.argv[1] == "typed"
    kind = AgentState if typed else Float64MultiArray
    topic = "/polymatch/agent_3/state"
    pub = node.create_publisher(kind, topic, 10)
    seconds = float(sys.argv[2])
    end, most = time.monotonic() + (30.0 if typed else seconds), 0
    while time.monotonic() < end:
        pub.publish(AgentState(agent=3) if typed else Float64MultiArray(data=[4.0, 1.0, 3.0]))
        most = max(most, pub.get_subscription_count())
        rclpy.spin_once(node, timeout_sec=0.05)
        if most and end - time.monotonic() > seconds:
            end = time.monotonic() + seconds
    print("MATCHED", most, flush=True)
    node.destroy_node()
    rclpy.shutdown()
""")


def _wait_for(ros, proc, word, seconds):
    import time

    end = time.monotonic() + seconds
    while word not in ros.output(proc) and time.monotonic() < end:
        time.sleep(0.05)
    return word in ros.output(proc)


def test_a_writer_of_another_type_on_an_agents_topic_is_never_matched(ros):
    """DDS matches a reader and a writer only of the same type (Jazzy's type hashes): a
    Float64MultiArray writer on agent_3/state, seen in the ROS graph, never reaches the run's
    AgentState reader, and an AgentState writer does (the positive control)."""
    reader = ros.start([PY, "-c", READER], timeout=90, name="reader")
    assert _wait_for(ros, reader, "READING", 30), ros.output(reader)
    wrong = ros.start([PY, "-c", WRITER, "wrong", str(WRONG_WRITES)], timeout=60,
                      name="wrong_writer")
    assert _wait_for(ros, reader, "WRONG", 45), ros.output(reader)
    right = ros.start([PY, "-c", WRITER, "typed", "3"], timeout=60, name="typed_writer")
    for proc in (reader, wrong, right):
        assert ros.wait(proc, 100) == 0, ros.output(proc)
    text = ros.output(reader)
    # in the graph while the reader listened, never matched, none heard
    assert re.search(r"^WRONG 1 0 0$", text, re.M), text
    assert re.search(r"^RIGHT 1 True$", text, re.M), text         # the run's own type matches
    assert "MATCHED 0" in ros.output(wrong), ros.output(wrong)
    assert "MATCHED 1" in ros.output(right), ros.output(right)
