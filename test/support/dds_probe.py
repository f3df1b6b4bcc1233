"""A minimal rclpy participant for the discovery and multi-host tests.

    python test/support/dds_probe.py --name NAME [--nodes K] [--messages M] [--expect NAME ...]
                             [--expect-count N] [--reliable] [--seconds S] [--participants P]

One process, one ROS context (one DDS participant), ``--nodes`` nodes in it; a publishing probe
with ``--participants P`` has P contexts (P participants, the senders ``NAME.J/<node>``), so
that a test of many participants does not pay for as many processes.  Each node publishes
on ``--topic`` the lines ``"<name>/<node> <seq>"``: ``--messages M`` sends exactly seq 0..M-1
(TRANSIENT_LOCAL + KEEP_ALL + RELIABLE, so a late reader still gets all of them), otherwise it
keeps sending every 0.2 s.  With ``--expect``/``--expect-count`` the process also listens and
prints one line ``heard: SENDER,...`` once it has heard every expected sender (all M messages of
each, in order, when ``--messages`` is given), then ``done`` and stays alive (still publishing)
until SIGINT/SIGTERM or ``--seconds``.  Lines that start with ``error:`` report a gap.
Exit code: 0 after hearing everything expected (or when nothing was expected), 1 otherwise.
"""

import argparse
import signal
import sys
import time

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String


def parse(argv):
    parser = argparse.ArgumentParser()
    parser.add_argument("--name", required=True)
    parser.add_argument("--topic", default="dds_probe")
    parser.add_argument("--nodes", type=int, default=1)
    parser.add_argument("--messages", type=int, default=0)
    parser.add_argument("--expect", nargs="*", default=[])
    parser.add_argument("--expect-count", type=int, default=0)
    parser.add_argument("--listen", action="store_true", help="subscribe, publish nothing")
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--participants", type=int, default=1,
                        help="contexts in this process (a publishing probe only)")
    args = parser.parse_args(argv)
    if args.participants > 1 and (args.listen or args.expect or args.expect_count):
        parser.error("--participants is for a probe that only publishes")
    return args


def qos_for(args):
    if args.messages:
        return QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.TRANSIENT_LOCAL)
    return QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)


class Listener:
    """Collects, per sender, the sequence numbers heard; says when every expected one is in."""

    def __init__(self, args):
        self.args = args
        self.heard = {}
        self.errors = 0
        self.complete = False

    def on_message(self, msg):
        sender, _, seq = msg.data.partition(" ")
        seqs = self.heard.setdefault(sender, [])
        if self.args.messages and seqs and int(seq) != seqs[-1] + 1:
            print(f"error: {sender} sent {seq} after {seqs[-1]}", flush=True)
            self.errors += 1
        seqs.append(int(seq))

    def senders_done(self):
        if not self.args.messages:
            return set(self.heard)
        wanted = list(range(self.args.messages))
        return {sender for sender, seqs in self.heard.items() if seqs == wanted}

    def check(self):
        done = self.senders_done()
        if self.args.expect and not set(self.args.expect) <= done:
            return False
        if len(done) < self.args.expect_count:
            return False
        if not self.complete:
            self.complete = True
            print("heard: " + ",".join(sorted(done)), flush=True)
            print(f"heard everything at {time.time():.1f}", flush=True)
            print("done", flush=True)
        return True


def main(argv=None):
    args = parse(sys.argv[1:] if argv is None else argv)
    stop = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    signal.signal(signal.SIGINT, lambda *_: stop.append(1))
    if args.participants > 1:
        return publish_from_participants(args, stop)
    rclpy.init(signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    executor = SingleThreadedExecutor()
    qos = qos_for(args)
    expecting = bool(args.expect or args.expect_count)
    listener = Listener(args)
    publishers, subscriptions = [], []
    for index in range(args.nodes):
        node = Node(node_name(args.name, index))
        executor.add_node(node)
        if not args.listen:
            publishers.append((f"{args.name}/{index}", node.create_publisher(String, args.topic,
                                                                            qos)))
        if expecting and index == 0:
            subscriptions.append(node.create_subscription(String, args.topic,
                                                          listener.on_message, qos))
    seq = 0
    next_send = 0.0
    end = time.monotonic() + args.seconds
    matched = 0
    print(f"ready at {time.time():.1f}", flush=True)
    while not stop and time.monotonic() < end:
        now = time.monotonic()
        if publishers and now >= next_send and (not args.messages or seq < args.messages):
            for sender, publisher in publishers:
                publisher.publish(String(data=f"{sender} {seq}"))
            seq += 1
            next_send = now + (0.02 if args.messages else 0.2)
        executor.spin_once(timeout_sec=0.05)
        if publishers and publishers[0][1].get_subscription_count() != matched:
            matched = publishers[0][1].get_subscription_count()
            print(f"matched subscriptions: {matched} at {time.time():.1f}", flush=True)
        if expecting:
            listener.check()
    ok = (listener.complete and listener.errors == 0) if expecting else True
    if expecting and not listener.complete:
        print("missing after timeout; heard: " + ",".join(sorted(listener.senders_done()))
              + f"; matched publishers: {subscriptions[0].get_publisher_count()}", flush=True)
    if publishers:
        print(f"matched subscriptions: {publishers[0][1].get_subscription_count()}", flush=True)
    executor.shutdown()
    rclpy.try_shutdown()
    return 0 if ok else 1


def node_name(name, index):
    return f"probe_{name}_{index}".replace("-", "_").replace(".", "_")


def publish_from_participants(args, stop):
    """``--participants P``: P contexts, each its own participant, whose nodes publish every
    0.2 s (or the ``--messages``) until SIGINT/SIGTERM or ``--seconds``; nothing spins (a
    publisher needs no executor, and discovery runs in each participant's own threads)."""
    qos = qos_for(args)
    contexts, publishers = [], []
    for participant in range(args.participants):
        context = rclpy.Context()
        rclpy.init(context=context,
                   signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
        contexts.append(context)
        sender = f"{args.name}.{participant}"
        for index in range(args.nodes):
            node = Node(node_name(sender, index), context=context)
            publishers.append((f"{sender}/{index}",
                               node.create_publisher(String, args.topic, qos)))
    print(f"ready at {time.time():.1f}", flush=True)
    end = time.monotonic() + args.seconds
    seq = 0
    while not stop and time.monotonic() < end:
        if not args.messages or seq < args.messages:
            for sender, publisher in publishers:
                publisher.publish(String(data=f"{sender} {seq}"))
            seq += 1
        time.sleep(0.02 if args.messages else 0.2)
    for context in contexts:
        rclpy.try_shutdown(context=context)
    return 0


if __name__ == "__main__":
    sys.exit(main())
