"""A scripted client of the ``/<ensemble>/match`` action for the action tests: sends one goal
from an rclpy ActionClient, prints every feedback and the result, and the agents' poses
(``agent_<i>/pose``, d <= 3) at the simulated time of the last feedback, as JSON lines.

    python test/support/match_probe.py --agents 8 [--tolerance X] [--time-limit S]
                                       [--cancel-after N] [--ensemble NAME]

Lines: ``{"feedback": {...}}`` per feedback, ``{"result": {...}, "status": CODE}``, then
``{"poses": {"<agent>": [x, y, z, qx, qy, qz, qw]}, "t": T}``.  ``--cancel-after N`` cancels
the goal after N feedbacks and prints ``{"cancel": <goals canceling>}``.  Every wait is
bounded (``BOUND`` s): the probe exits 3 when one runs out.
"""

import argparse
import json
import math
import sys
import time

import rclpy
from geometry_msgs.msg import PoseStamped
from rclpy.action import ActionClient
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy

from polymatch_interfaces.action import Match
from polymatch_ros.ros.process.teardown import end_process, teardown_watchdog

BOUND = 150.0
FEEDBACK_FIELDS = ("t", "diameter", "diameter_centroid", "diameter_rotation", "agents_heard",
                   "n_agents", "certificate")


def emit(**line):
    print(json.dumps(line), flush=True)


class Probe:
    def __init__(self, args):
        self.args = args
        self.node = Node("match_probe")
        self.client = ActionClient(self.node, Match, f"/{args.ensemble}/match")
        self.feedback = []
        self.poses = {}  # stamp (ns) -> {agent: [x, y, z, qx, qy, qz, qw]}
        qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
        for a in range(args.agents):
            self.node.create_subscription(PoseStamped, f"/{args.ensemble}/agent_{a}/pose",
                                          self._pose(a), qos)

    def _pose(self, agent):
        def take(msg):
            ns = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
            p, q = msg.pose.position, msg.pose.orientation
            self.poses.setdefault(ns, {})[agent] = [p.x, p.y, p.z, q.x, q.y, q.z, q.w]
        return take

    def _feedback(self, msg):
        fb = {k: getattr(msg.feedback, k) for k in FEEDBACK_FIELDS}
        self.feedback.append(fb)
        emit(feedback=fb)

    def until(self, done, what):
        deadline = time.monotonic() + BOUND
        while not done():
            if time.monotonic() > deadline:
                emit(timeout=what)
                end_process(3)
            rclpy.spin_once(self.node, timeout_sec=0.05)

    def spin_for(self, seconds):
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            rclpy.spin_once(self.node, timeout_sec=0.05)

    def run(self):
        args = self.args
        self.until(self.client.server_is_ready, "the action server")
        goal = Match.Goal(tolerance=args.tolerance, time_limit=args.time_limit)
        sent = self.client.send_goal_async(goal, feedback_callback=self._feedback)
        self.until(sent.done, "the goal's acceptance")
        handle = sent.result()
        emit(accepted=handle.accepted)
        if not handle.accepted:
            return 1
        if args.cancel_after is not None:
            self.until(lambda: len(self.feedback) >= args.cancel_after, "feedback")
            canceling = handle.cancel_goal_async()
            self.until(canceling.done, "the cancel's answer")
            emit(cancel=len(canceling.result().goals_canceling))
        result = handle.get_result_async()
        self.until(result.done, "the result")
        self.spin_for(0.5)  # feedback still on its way
        res = result.result().result
        emit(result={"matched": res.matched, "matched_at": _num(res.matched_at),
                     "diameter": _num(res.diameter), "reason": res.reason},
             status=result.result().status)
        t_last = max(fb["t"] for fb in self.feedback)
        ns = round(t_last * 1e9)
        self.until(lambda: len(self.poses.get(ns, {})) == args.agents, "the poses of t_last")
        emit(t=t_last, poses={str(a): p for a, p in sorted(self.poses[ns].items())})
        return 0


def _num(x):
    return None if math.isnan(x) else x


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--agents", type=int, required=True)
    ap.add_argument("--tolerance", type=float, default=0.0)
    ap.add_argument("--time-limit", type=float, default=0.0)
    ap.add_argument("--cancel-after", type=int)
    ap.add_argument("--ensemble", default="polymatch")
    args = ap.parse_args()
    rclpy.init(args=[])
    probe = Probe(args)
    code = probe.run()
    with teardown_watchdog(exit_code=code):
        probe.node.destroy_node()
        rclpy.shutdown()
    end_process(code)


if __name__ == "__main__":
    sys.exit(main())
