"""A realtime tick's take of its peers' readers (``LeanReaders.take_newest``): the newest state
each reader holds, nothing waited for, no callback run.

A probe process publishes states with known stamps on two peers' topics (readers that keep
every sample, so that several wait), then takes them: the newest of each reader in the order the
readers were made, the older ones counted as taken, an empty reader absent, and a bound that
leaves the rest for the next take.  The oracle is the publication order written in the probe.
"""

import ast
import re
import textwrap

from ros_harness import PY, needs_ros

pytestmark = needs_ros

PROBE = textwrap.dedent("""
    import time, rclpy
    from polymatch_ros.ros import wire
    from polymatch_ros.ros.wire.intake import LeanReaders
    rclpy.init()
    node = rclpy.create_node("take_probe", namespace="/take_probe")
    readers = LeanReaders(node, "_peers")
    called = []
    for agent in (3, 5, 7):
        readers.subscribe("state", called.append, 2, agent, wire.Mode.LOCKSTEP)
    pubs = {a: wire.publisher(node, "state", 2, a) for a in (3, 5)}
    deadline = time.monotonic() + 20
    while any(p.get_subscription_count() < 1 for p in pubs.values()):
        assert time.monotonic() < deadline, "no match"
        time.sleep(0.05)
    msg_type = wire.message_type("state")
    sent = {3: [1, 2, 3, 4, 5], 5: [7, 8]}
    for agent, stamps in sent.items():
        for sec in stamps:
            msg = msg_type(run_id=1, agent=agent)
            msg.header.stamp.sec = sec
            pubs[agent].publish(msg)
    time.sleep(1.5)  # every sample delivered to the readers (reliable, on loopback)
    first = [(i, m.agent, m.header.stamp.sec) for i, m, _ in readers.take_newest(bound=3)]
    after_first = readers.taken
    second = [(i, m.agent, m.header.stamp.sec) for i, m, _ in readers.take_newest(bound=3)]
    third = readers.take_newest(bound=3)
    print("TAKE", first, after_first, second, readers.taken, len(third), len(called), flush=True)
    readers.destroy()
    node.destroy_node()
    rclpy.shutdown()
""")


def test_a_take_gives_each_readers_newest_state_within_the_bound(ros):
    proc = ros.start([PY, "-c", PROBE], timeout=60, name="take_probe")
    assert ros.wait(proc, 70) == 0, ros.output(proc)
    line = re.search(r"^TAKE (\[.*?\]) (\d+) (\[.*?\]) (\d+) (\d+) (\d+)$", ros.output(proc),
                     re.M)
    assert line, ros.output(proc)
    first, second = ast.literal_eval(line.group(1)), ast.literal_eval(line.group(3))
    after_first, taken, third, called = (int(line.group(k)) for k in (2, 4, 5, 6))
    # agent 3 sent 1..5: the first take of at most 3 ends at 3, the next one at 5; agent 5 sent
    # 7, 8: both taken at once; agent 7 (reader 2) sent nothing
    assert first == [(0, 3, 3), (1, 5, 8)], line.group(0)
    assert second == [(0, 3, 5)], line.group(0)
    assert (after_first, taken, third, called) == (5, 7, 0, 0), line.group(0)
