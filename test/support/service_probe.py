"""A scripted rclpy client for the service tests: calls std_srvs services, watches run records
and one agent's poses, and prints what it saw, one line per action.

    python test/support/service_probe.py ACTION [ACTION ...]

Actions (each word-separated inside one argument):
  call NAME [true|false]   call a Trigger service (SetBool with true/false); prints
                           ``RESULT NAME <success> <message>``
  until_t T                wait until every agent's run record reached simulated time T
  t                        prints ``T <the slowest agent's time>``
  sleep S                  spin for S seconds
  pose AGENT               prints ``POSE <stamp> <x...>`` of AGENT's newest pose
  silent AGENT S           prints ``SILENT <True|False>``: no pose of AGENT for S seconds
  lifecycle NODE LABEL     a lifecycle transition (configure, activate, deactivate, cleanup,
                           shutdown); prints ``LIFECYCLE LABEL <success>``
  state NODE               prints ``STATE <label>`` (lifecycle_msgs GetState)
  publishers TOPIC N       waits (10 s at most) for N publishers; prints ``PUBLISHERS <count>``
Every wait is bounded (60 s): the probe exits 3 when one runs out.
"""

import sys
import time

import rclpy
from geometry_msgs.msg import PoseStamped
from rclpy.node import Node
from std_srvs.srv import SetBool, Trigger

from polymatch_interfaces.msg import RunRecord as RunRecordMsg
from polymatch_ros.ros.process.teardown import end_process, teardown_watchdog
from polymatch_ros.ros.wire import RunRecord
from polymatch_ros.ros.wire.service_call import call_service

BOUND = 60.0


class Probe:
    def __init__(self):
        self.node = Node("service_probe")
        self.times = {}
        self.size = 0
        self.poses = {}
        latched = rclpy.qos.QoSProfile(
            depth=100,
            reliability=rclpy.qos.ReliabilityPolicy.RELIABLE,
            durability=rclpy.qos.DurabilityPolicy.TRANSIENT_LOCAL,
        )
        self.node.create_subscription(RunRecordMsg, "/polymatch/status", self._status, latched)

    def _status(self, msg):
        rec = RunRecord.from_msg(msg)
        if rec is not None and rec.role == "agent":
            self.times[rec.agents] = rec.t
            self.size = max(self.size, rec.n_agents)

    def spin(self, seconds):
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            rclpy.spin_once(self.node, timeout_sec=min(0.05, max(0.0, end - time.monotonic())))

    def wait(self, predicate, what):
        end = time.monotonic() + BOUND
        while not predicate():
            if time.monotonic() > end:
                print(f"TIMEOUT {what}", flush=True)
                sys.exit(3)
            rclpy.spin_once(self.node, timeout_sec=0.05)

    def call(self, name, value=None):
        kind = Trigger if value is None else SetBool
        request = kind.Request()
        if value is not None:
            request.data = value == "true"
        answer = self._call(kind, name, request)
        print(f"RESULT {name} {answer.success} {answer.message}", flush=True)

    def slowest(self):
        """The slowest agent's time, once a record of every agent of the ensemble (its size as
        the records give it) has come: None before (the first records to come may all be of
        agents ahead of the others)."""
        heard = {agent for agents in self.times for agent in agents}
        if not self.times or len(heard) < self.size:
            return None
        return min(self.times.values())

    def until_t(self, t):
        self.wait(lambda: self.slowest() is not None and self.slowest() >= float(t), f"t {t}")

    def pose(self, agent):
        topic = self._subscribe_pose(agent)
        self.wait(lambda: self.poses[topic] is not None, f"a pose on {topic}")
        msg = self.poses[topic]
        p, q = msg.pose.position, msg.pose.orientation
        stamp = msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
        values = (p.x, p.y, p.z, q.x, q.y, q.z, q.w)
        print(f"POSE {stamp!r} " + " ".join(repr(v) for v in values), flush=True)


    def _subscribe_pose(self, agent):
        topic = f"/polymatch/agent_{agent}/pose"
        if topic not in self.poses:

            def keep(msg, topic=topic):
                self.poses[topic] = msg

            self.node.create_subscription(PoseStamped, topic, keep, 10)
        self.poses[topic] = None
        return topic

    def silent(self, agent, seconds):
        topic = self._subscribe_pose(agent)
        self.spin(float(seconds))
        print(f"SILENT {self.poses[topic] is None}", flush=True)

    def _call(self, kind, name, request):
        """The response of service ``name`` (the package's one bounded call)."""
        answer = call_service(self.node, kind, name, request, BOUND)
        if not answer.answered:
            print(f"TIMEOUT {answer.failure}", flush=True)
            sys.exit(3)
        return answer.response

    def lifecycle(self, node, label):
        from lifecycle_msgs.msg import Transition
        from lifecycle_msgs.srv import ChangeState, GetState

        state = self._call(GetState, f"{node}/get_state", GetState.Request())
        ids = {"configure": Transition.TRANSITION_CONFIGURE,
               "cleanup": Transition.TRANSITION_CLEANUP,
               "activate": Transition.TRANSITION_ACTIVATE,
               "deactivate": Transition.TRANSITION_DEACTIVATE,
               "shutdown": {"unconfigured": Transition.TRANSITION_UNCONFIGURED_SHUTDOWN,
                            "inactive": Transition.TRANSITION_INACTIVE_SHUTDOWN,
                            "active": Transition.TRANSITION_ACTIVE_SHUTDOWN}
               .get(state.current_state.label)}
        request = ChangeState.Request()
        request.transition.id = ids[label]
        answer = self._call(ChangeState, f"{node}/change_state", request)
        print(f"LIFECYCLE {label} {answer.success}", flush=True)

    def state(self, node):
        from lifecycle_msgs.srv import GetState

        answer = self._call(GetState, f"{node}/get_state", GetState.Request())
        print(f"STATE {answer.current_state.label}", flush=True)

    def publishers(self, topic, wanted):
        """Wait (at most 10 s) until ``topic`` has ``wanted`` publishers; print the count."""
        end = time.monotonic() + 10.0
        while self.node.count_publishers(topic) != int(wanted) and time.monotonic() < end:
            rclpy.spin_once(self.node, timeout_sec=0.1)
        print(f"PUBLISHERS {self.node.count_publishers(topic)}", flush=True)


def main(actions):
    rclpy.init()
    probe = Probe()
    for action in actions:
        verb, *args = action.split()
        if verb == "call":
            probe.call(*args)
        elif verb == "until_t":
            probe.until_t(*args)
        elif verb == "t":
            probe.spin(1.5)  # the agents' records come once a second
            print(f"T {probe.slowest()!r}", flush=True)
        elif verb == "sleep":
            probe.spin(float(args[0]))
        elif verb in ("pose", "silent", "lifecycle", "state", "publishers"):
            getattr(probe, verb)(*args)
        else:
            print(f"unknown action {action!r}", flush=True)
            return 2
    with teardown_watchdog(exit_code=0):  # Fast DDS's rare teardown spin
        probe.node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    end_process(main(sys.argv[1:]))
