"""A rogue publisher for the robustness tests: floods one agent's topics.

    python test/support/rogue_publisher.py ENSEMBLE AGENT SECONDS [STAMP] [--run-id ID]

Sends, at ~100 Hz each: PoseStamped with NaN positions, PoseStamped with a quaternion of
norm 2, lockstep stage rows with NaN data (stamped with the run's id, ID: a rogue that knows
it), a foreign run id, or no rows, agent states (``wire.exchange``) with NaN data (the run's id)
or a foreign run id, and another run's final state on the
latched ``final_state``.  With STAMP it sends instead, at 20 Hz, well-formed states
of a 2-D agent far away (centroid (50, 0), rotation 0.3 rad) stamped STAMP (late in the run:
newer than any real pose), on the agent's pose topic and on its exchange with a foreign run
id, and a monitor's run record of that run on the status topic: agents all heard, matched
(diameter 0) at STAMP.  That is what another run, or a stale process of an earlier one, would
send.  It is started by the test in the test's own ROS domain (loopback discovery) under
`timeout`.
"""

import math
import sys
import time

import numpy as np
import rclpy
from geometry_msgs.msg import PoseStamped
from rclpy.node import Node

from polymatch_interfaces.msg import AgentState, StageRows
from polymatch_ros.core.so import SO2
from polymatch_ros.ros import wire

FOREIGN_RUN = 12345
FAR = (50.0, 0.0)
ANGLE = 0.3
AGENTS = 8              # the scene's (congruent_triangles)


def well_formed(pose, exchange, status, agent, stamp):
    """A far-away pose stamped ``stamp`` on the pose topic and on the exchange, and a monitor's
    record of a matched ensemble at ``stamp`` (another run's)."""
    grp = SO2()
    record = wire.RunRecord(role="monitor", mode="realtime", t=stamp, diameter=0.0,
                            agents_heard=AGENTS, reports=1, run_id=FOREIGN_RUN)
    status.publish(record.to_msg())
    pose.publish(wire.pose_message(grp, stamp, np.array(FAR), np.array([ANGLE]), "world"))
    exchange.publish(wire.encode_exchange(AgentState(), grp, FOREIGN_RUN, agent, stamp,
                                          np.array(FAR), np.array([ANGLE])))


def malformed(pose, stage, exchange, final, agent, k, run_id):
    """NaN and non-unit poses, stages with NaN data, a foreign run id or no header, exchange
    messages with NaN data or a foreign run id, and another run's well-formed final state (far
    away, stamped t = 1) on the latched final exchange the runner summarises."""
    p = PoseStamped()
    p.header.frame_id = "world"
    p.header.stamp.sec = k
    if k % 2:
        p.pose.position.x = math.nan
        p.pose.orientation.w = 1.0
    else:
        p.pose.orientation.w = 2.0                      # quaternion far from unit norm
    pose.publish(p)
    fields = {"x": [0.0, 0.0], "rot": [math.nan if k % 2 else 0.3]}
    msg = wire.encode_stage(StageRows(), FOREIGN_RUN if k % 2 == 0 else run_id, agent, k, 0,
                            0, 0.0, fields)
    stage.publish(msg)
    stage.publish(StageRows(sender=agent, t=0.0))       # no rows at all

    grp = SO2()
    x = np.array([math.nan if k % 2 else 0.0, 0.0])
    exchange.publish(wire.encode_exchange(AgentState(), grp, run_id if k % 2 else FOREIGN_RUN,
                                          agent, 0.0, x, np.array([0.3])))
    final.publish(wire.encode_exchange(AgentState(), grp, FOREIGN_RUN, agent, 1.0,
                                       np.array(FAR), np.array([ANGLE])))


def main():
    argv, run_id = sys.argv[1:], 0
    if "--run-id" in argv:
        i = argv.index("--run-id")
        run_id, argv = int(argv[i + 1]), argv[:i] + argv[i + 2:]
    ensemble, agent, seconds = argv[0], int(argv[1]), float(argv[2])
    stamp = float(argv[3]) if len(argv) > 3 else None
    rclpy.init()
    node = Node("rogue")
    qos = wire.qos_profiles()
    pose = node.create_publisher(PoseStamped, wire.full_name(ensemble, "pose", agent), qos["pose"])
    stage = node.create_publisher(StageRows, wire.full_name(
        ensemble, "stage", agent), qos["stage"])
    exchange = node.create_publisher(AgentState, wire.full_name(
        ensemble, "state", agent), qos["pose"])
    final = node.create_publisher(AgentState, wire.full_name(
        ensemble, "final_state", agent), qos["latched"])
    status = node.create_publisher(wire.message_type("record"), wire.full_name(ensemble, "status"),
                                   qos["status"])
    end = time.monotonic() + seconds
    k = 0
    while time.monotonic() < end:
        if stamp is None:
            malformed(pose, stage, exchange, final, agent, k, run_id)
        else:
            well_formed(pose, exchange, status, agent, stamp)
        k += 1
        if k == 20:
            print("rogue: flooding", flush=True)           # the test starts the run after this
        # malformed: a flood; well-formed: at a run's own rate (a realtime run at 20 Hz)
        rclpy.spin_once(node, timeout_sec=0.01 if stamp is None else 0.05)
    print(f"rogue: sent {k} rounds of messages", flush=True)
    node.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    main()
