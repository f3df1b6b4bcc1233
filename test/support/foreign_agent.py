"""An agent written from the protocol alone: the ``.msg`` files of polymatch_interfaces and the
ROS interface guide (docs/guide/ros-interface.md), nothing of ``polymatch_ros``.

    python test/support/foreign_agent.py SCENE AGENT RUN_ID SECONDS [ENSEMBLE]

It joins a realtime ensemble as agent AGENT of the first-order model (A-2) of a 2-D scene
with one group: every tick (20 Hz) it takes the newest ``AgentState`` of each peer
(``/<ensemble>/agent_<j>/state``, run id RUN_ID), follows the ensemble's simulated clock (the
newest peer stamp) and steps its own state by that much with the Lie-Euler step of (A-2):

    x_i' = (kappa/N) sum_k (x_k - x_i)
    O_i' = W_i O_i,  W_i = (kappa/2N) (S O_i^T - O_i S^T),  S = sum_k O_k

(O_i <- expm(h W_i) O_i stays in SO(2)), and publishes its own ``AgentState``; once a second
its ``RunRecord``, latched, on ``/<ensemble>/status`` (the runner starts the ensemble's clock
once every agent's record is there).  On the
ensemble's STOP (``ControlCommand`` on ``/<ensemble>/control``) or at t_end it publishes its
final state, latched, on ``agent_<i>/final_state``, and keeps it until RECEIVED or 30 s.
Its initial state is its own: centroid (4, -3) relative to the scene's origin, 2.5 rad.
"""

import array
import sys
import time

import numpy as np
import rclpy
import yaml
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from scipy.linalg import expm

from polymatch_interfaces.msg import AgentState, ControlCommand, RunRecord

RATE = 20.0
HOLD = 30.0


def qos(depth, reliable, latched):
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST, depth=depth,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)


class ForeignAgent:
    def __init__(self, node, scene, me, run_id, ensemble):
        self.node, self.me, self.run_id = node, me, run_id
        self.kappa = float(scene["model"]["kappa"])
        self.n = int(sum(g["count"] for g in scene["groups"]))
        self.t_end = float(scene["time"]["t_end"])
        self.x = np.array([4.0, -3.0])
        self.rot = rotation(2.5)
        self.t = None                 # simulated time, once a peer is heard
        self.peers = {}               # agent -> (t, x, O): its newest state
        self.stopped = self.received = False
        self.dropped = self.steps = 0
        ns = "/" + ensemble
        self.status = node.create_publisher(RunRecord, f"{ns}/status", qos(1, True, True))
        self.pub = node.create_publisher(AgentState, f"{ns}/agent_{me}/state",
                                         qos(100, True, False))
        self.final = node.create_publisher(AgentState, f"{ns}/agent_{me}/final_state",
                                           qos(1, True, True))
        for j in range(self.n):
            if j != me:
                node.create_subscription(AgentState, f"{ns}/agent_{j}/state", self.hear(j),
                                         qos(1, False, False))
        node.create_subscription(ControlCommand, f"{ns}/control", self.command,
                                 qos(10, True, False))

    def hear(self, j):
        def receive(msg):
            t = msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
            values = np.array(msg.centroid), np.array(msg.rotation)
            if (msg.run_id != self.run_id or msg.agent != j or len(values[0]) != 2
                    or len(values[1]) != 4 or not np.all(np.isfinite(np.concatenate(values)))):
                self.dropped += 1
                return
            if j not in self.peers or t >= self.peers[j][0]:
                self.peers[j] = (t, values[0], values[1].reshape(2, 2))
        return receive

    def command(self, msg):
        if msg.command == ControlCommand.STOP:
            self.stopped = True
        elif msg.command == ControlCommand.RECEIVED:
            self.received = True

    def tick(self):
        if not self.peers:
            return
        newest = min(max(p[0] for p in self.peers.values()), self.t_end)
        if self.t is None:
            self.t = newest
        h = newest - self.t
        if h > 0:
            xs = [self.x] + [p[1] for p in self.peers.values()]
            rots = [self.rot] + [p[2] for p in self.peers.values()]
            s = np.sum(rots, axis=0)
            w = self.kappa / (2 * self.n) * (s @ self.rot.T - self.rot @ s.T)
            self.x = self.x + h * self.kappa / self.n * np.sum([x - self.x for x in xs], axis=0)
            self.rot = expm(h * w) @ self.rot
            self.t = newest
            self.steps += 1
        self.pub.publish(self.state())

    def state(self):
        msg = AgentState(run_id=self.run_id, agent=self.me)
        ns = int(round(self.t * 1e9))
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(ns, 10**9)
        msg.header.frame_id = "world"
        msg.centroid = array.array("d", self.x.tolist())
        msg.rotation = array.array("d", self.rot.ravel().tolist())
        return msg


    def record(self, finished=False):
        """This process's RunRecord: NaN and -1 where a field does not apply (RunRecord.msg)."""
        nan = float("nan")
        msg = RunRecord(run_id=self.run_id, role="agent", mode="realtime", t=self.t or 0.0,
                        agents=[self.me], finished=finished, steps=self.steps,
                        rounds=self.steps, matched_after=nan, diameter=nan,
                        n_agents=self.n, node=self.node.get_fully_qualified_name(),
                        resumed_at=-1, first_round_at=nan)
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(time.time_ns(), 10**9)
        return msg


def rotation(theta):
    return np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])


def main():
    path, me, run_id, seconds = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), float(sys.argv[4])
    ensemble = sys.argv[5] if len(sys.argv) > 5 else "polymatch"
    with open(path) as fh:
        scene = yaml.safe_load(fh)
    rclpy.init()
    node = rclpy.create_node(f"foreign_agent_{me}")
    agent = ForeignAgent(node, scene, me, run_id, ensemble)
    end = time.monotonic() + seconds
    next_tick = next_record = time.monotonic()
    while time.monotonic() < end and not agent.stopped and (agent.t or 0.0) < agent.t_end:
        rclpy.spin_once(node, timeout_sec=max(0.0, next_tick - time.monotonic()))
        if time.monotonic() >= next_tick:
            agent.tick()
            next_tick += 1.0 / RATE
        if time.monotonic() >= next_record:
            agent.status.publish(agent.record())
            next_record += 1.0
    if agent.t is not None:
        agent.final.publish(agent.state())
        agent.status.publish(agent.record(finished=True))
        print(f"foreign agent {me}: final t = {agent.t:.3f}, x = {agent.x.tolist()}, "
              f"dropped {agent.dropped}", flush=True)
    hold = time.monotonic() + HOLD
    while not agent.received and time.monotonic() < min(hold, end):
        rclpy.spin_once(node, timeout_sec=0.1)
    node.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    main()
