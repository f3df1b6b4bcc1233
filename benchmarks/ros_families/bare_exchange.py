"""The bare transport's all-to-all lockstep exchange: the limit for the agents' round rate.

    python -m benchmarks.ros_families.bare_exchange INDEX K ROUNDS [PAYLOAD]
        [--executor single|events] [--message untyped|typed]

Process INDEX of K publishes one message of PAYLOAD doubles per round on
/polymatch_bare/p<INDEX> (untyped: a std_msgs/Float64MultiArray; typed: the run's own
polymatch_interfaces/msg/StageRows, the round in its step field and the doubles in its
rotations, as a lockstep agent fills it) and waits, spinning the same executor with the
same QoS and the same lean node and executor as the agents' lockstep stages
(RELIABLE, VOLATILE; readers KEEP_ALL),
until it has every other process's message of that round.  No numerics.  It waits
for discovery exactly as an agent does (its readers matched a writer of every peer,
its writer matched K - 1 readers) and prints one line; as an agent's, its rate counts the
rounds after the first, which waits for the last peer to start:

    bare typed 3/8: RATE rounds/s over 400 rounds; matched after SECONDS s

(its rates: ``docs/bench/distributed.md``)

The bare realtime tick, the limit for one agent a process in realtime:

    python -m benchmarks.ros_families.bare_exchange tick INDEX K RATE SECONDS

Process INDEX of K publishes one polymatch_interfaces/msg/AgentState (a d = 2 pose, as a
realtime agent fills it) per tick at RATE Hz on /polymatch_bare/s<INDEX>, with the QoS of the
agents' state topic (writers RELIABLE, readers BEST_EFFORT depth 1), and takes the newest
message of each peer's reader at each tick without an executor (as the agents do).  No
numerics, no checks.  It waits for discovery as above, then ticks for SECONDS and prints its
CPU time (every thread) per tick:

    bare tick 3/16: CPU MS ms a tick over TICKS ticks at RATE Hz; HEARD of PEERS peers heard

(its figures: ``docs/bench/realtime_scale.md``)
"""

import array
import sys
import time


def _option(argv, name, default):
    """(the value of ``--name`` or ``default``, argv without it)."""
    if name not in argv:
        return default, argv
    i = argv.index(name)
    return argv[i + 1], argv[:i] + argv[i + 2:]


def _parse(argv):
    """(INDEX, K, ROUNDS, PAYLOAD, executor kind, message kind) from the command line."""
    executor_kind, argv = _option(argv, "--executor", "single")
    message_kind, argv = _option(argv, "--message", "untyped")
    payload = int(argv[3]) if len(argv) > 3 else 10
    return int(argv[0]), int(argv[1]), int(argv[2]), payload, executor_kind, message_kind


class Untyped:
    """Float64MultiArray: the round as the first double."""

    def __init__(self):
        from std_msgs.msg import Float64MultiArray

        self.type = Float64MultiArray

    def fill(self, msg, r, filler):
        msg.data = array.array("d", [float(r)] + filler)

    @staticmethod
    def round_of(msg):
        return int(msg.data[0])


class Typed:
    """StageRows: the round in ``step``, the doubles in ``rotations`` (one agent's row)."""

    def __init__(self):
        from polymatch_interfaces.msg import StageRows

        self.type = StageRows
        self.agents = array.array("I", [0])

    def fill(self, msg, r, filler):
        msg.step, msg.t, msg.agents = r, float(r), self.agents
        msg.rotations = array.array("d", [float(r)] + filler)

    @staticmethod
    def round_of(msg):
        return msg.step


MESSAGES = {"untyped": Untyped, "typed": Typed}


def _endpoints(node, me, k, inbox, kind):
    """This process's writer and a reader of every peer's topic; a reader files each round's
    message under ``inbox[round]``."""
    from polymatch_ros.ros import wire
    from polymatch_ros.ros.wire.intake import quiet_events

    pub_events, sub_events = quiet_events()
    qos = wire.qos_profiles()
    pub = node.create_publisher(kind.type, f"/polymatch_bare/p{me}", qos["stage"],
                                event_callbacks=pub_events)

    def callback(peer):
        def receive(msg):
            inbox.setdefault(kind.round_of(msg), set()).add(peer)
        return receive

    subs = [
        node.create_subscription(
            kind.type,
            f"/polymatch_bare/p{p}",
            callback(p),
            qos["stage_in"],
            event_callbacks=sub_events,
        )
        for p in range(k)
        if p != me
    ]
    return pub, subs


def _events_executor(node, executor):
    """Move ``node`` from ``executor`` to a new rclpy EventsExecutor."""
    from rclpy.experimental.events_executor import EventsExecutor

    executor.remove_node(node)
    executor = EventsExecutor()
    executor.add_node(node)
    return executor


def _wait_matched(executor, pub, subs, k):
    """Spin until every peer's writer and K - 1 readers are matched; the seconds it took."""
    t_node = time.monotonic()
    while not (
        all(s.get_publisher_count() >= 1 for s in subs) and pub.get_subscription_count() >= k - 1
    ):
        executor.spin_once(timeout_sec=0.05)
    return time.monotonic() - t_node


def _exchange(executor, pub, inbox, k, rounds, payload, kind):
    """``rounds`` lockstep rounds: publish, then spin until every peer's message of the round
    is in; the wall seconds."""
    msg = kind.type()
    filler = [0.5] * (payload - 1)
    t0 = time.perf_counter()
    for r in range(rounds):
        kind.fill(msg, r, filler)
        pub.publish(msg)
        while len(inbox.get(r, ())) < k - 1:
            executor.spin_once(timeout_sec=1.0)
        inbox.pop(r, None)
        if r == 0:  # it waited for the last peer to start: time the rounds after it
            t0 = time.perf_counter()
    return time.perf_counter() - t0


def _tick_endpoints(node, me, k):
    """This process's state writer and a reader of every peer's, with the agents' QoS."""
    from polymatch_interfaces.msg import AgentState
    from polymatch_ros.ros import wire
    from polymatch_ros.ros.wire.intake import quiet_events

    pub_events, sub_events = quiet_events()
    qos = wire.qos_profiles()
    pub = node.create_publisher(AgentState, f"/polymatch_bare/s{me}", qos["pose"],
                                event_callbacks=pub_events)
    subs = [node.create_subscription(AgentState, f"/polymatch_bare/s{p}", lambda _msg: None,
                                     qos["latest"], event_callbacks=sub_events)
            for p in range(k) if p != me]
    return pub, subs


def _ticks(pub, subs, me, rate, seconds):
    """Tick at ``rate`` Hz for ``seconds``: publish a state, take each reader's newest message;
    (ticks, process CPU seconds over them, peers heard at least once)."""
    from polymatch_interfaces.msg import AgentState

    period, ticks = 1.0 / rate, int(round(rate * seconds))
    heard: set[int] = set()
    next_tick = time.monotonic()
    cpu0 = time.process_time()
    for n in range(ticks):
        next_tick += period
        time.sleep(max(0.0, next_tick - time.monotonic()))
        msg = AgentState()
        msg.header.stamp.sec = int(n // rate)
        msg.header.frame_id, msg.run_id, msg.agent = "world", 1, me
        msg.centroid = array.array("d", [0.5 * n, 0.25])
        msg.rotation = array.array("d", [1.0, 0.0, 0.0, 1.0])
        pub.publish(msg)
        for i, sub in enumerate(subs):
            newest = None
            while True:
                with sub.handle:
                    got = sub.handle.take_message(sub.msg_type, sub.raw)
                if got is None:
                    break
                newest = got
            if newest is not None:
                heard.add(i)
    return ticks, time.process_time() - cpu0, len(heard)


def tick_main(argv):
    me, k, rate, seconds = int(argv[0]), int(argv[1]), float(argv[2]), float(argv[3])
    import rclpy

    rclpy.init()
    from polymatch_ros.ros.wire.intake import lean_node

    node, executor = lean_node(f"bare_tick_{me}")
    pub, subs = _tick_endpoints(node, me, k)
    _wait_matched(executor, pub, subs, k)
    ticks, cpu, heard = _ticks(pub, subs, me, rate, seconds)
    print(f"bare tick {me}/{k}: CPU {cpu / ticks * 1e3:.3f} ms a tick over {ticks} ticks at "
          f"{rate:g} Hz; {heard} of {k - 1} peers heard", flush=True)
    node.destroy_node()
    rclpy.shutdown()


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["tick"]:
        return tick_main(argv[1:])
    me, k, rounds, payload, executor_kind, message_kind = _parse(argv)
    t_start = time.monotonic()
    import rclpy
    from rclpy.duration import Duration

    rclpy.init()
    from polymatch_ros.ros.wire.intake import lean_node
    node, executor = lean_node(f"bare_{me}")
    inbox = {}
    kind = MESSAGES[message_kind]()
    pub, subs = _endpoints(node, me, k, inbox, kind)
    if executor_kind == "events":
        executor = _events_executor(node, executor)
    matched = _wait_matched(executor, pub, subs, k)
    wall = _exchange(executor, pub, inbox, k, rounds, payload, kind)
    pub.wait_for_all_acked(Duration(seconds=5))
    print(
        f"bare {message_kind} {me}/{k}: {(rounds - 1) / wall:.1f} rounds/s over {rounds} rounds; "
        f"matched after {matched:.2f} s "
        f"({time.monotonic() - t_start - wall:.2f} s from process start)",
        flush=True,
    )
    node.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    main()
