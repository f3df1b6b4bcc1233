"""Every topic of an ensemble: its name, message type and QoS, in one table.

Names are relative: they resolve in the node's namespace, which is the ensemble
(``-r __ns:=/polymatch``, the default), so ``agent_3/pose`` is
``/polymatch/agent_3/pose`` and ``--ros-args -r`` remaps apply.  ``/diagnostics``
is the ROS-wide aggregate topic and stays absolute.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from .modes import Mode

if TYPE_CHECKING:
    from rclpy.node import Node
    from rclpy.publisher import Publisher
    from rclpy.qos import QoSProfile
    from rclpy.subscription import Subscription

DEFAULT_ENSEMBLE = "polymatch"


@dataclass(frozen=True)
class Topic:
    """name: relative pattern ({agent} filled in); kind: message kind (see ``message_type``);
    qos: the writers' profile; reader_qos: the readers' profile per mode (None = qos)."""

    name: str
    kind: str
    qos: str
    realtime_reader_qos: str | None = None
    reader_qos: str | None = None


TOPICS = {
    # d <= 3: geometry_msgs/PoseStamped and TwistStamped; d >= 4: polymatch_interfaces PoseNd,
    # TwistNd
    "pose": Topic("agent_{agent}/pose", "pose", "pose", realtime_reader_qos="latest"),
    "twist": Topic("agent_{agent}/twist", "twist", "pose", realtime_reader_qos="latest"),
    # the run's own exchange (wire.exchange): each state with the run's id, for the peers and
    # the monitor; the pose and twist topics above are for people and tools
    "state": Topic("agent_{agent}/state", "state", "pose", realtime_reader_qos="latest"),
    # K agents per process (lockstep, realtime): the states of block b's agents, one message a
    # step or tick
    "state_block": Topic("states/block_{agent}", "state_block", "pose",
                         realtime_reader_qos="latest"),
    # the final state, latched, for people and tools
    "final_pose": Topic("agent_{agent}/final_pose", "pose", "latched"),
    "final_twist": Topic("agent_{agent}/final_twist", "twist", "latched"),
    # the final state with the run's id: what the runner summarises
    "final_state": Topic("agent_{agent}/final_state", "state", "latched",
                         reader_qos="final_in"),
    # lockstep with K agents per process: the final states of block b's agents, latched
    "final_state_block": Topic("states/final_block_{agent}", "state_block", "latched",
                               reader_qos="final_in"),
    "stage": Topic("agent_{agent}/stage", "stage", "stage", reader_qos="stage_in"),
    # lockstep with K agents per process: the rows of block b (agents bK .. bK + K - 1)
    "stage_block": Topic("stages/block_{agent}", "stage", "stage", reader_qos="stage_in"),
    "control": Topic("control", "control", "control"),
    # the run record of every agent process and the monitor (wire.run_record), latched per writer
    "status": Topic("status", "record", "status", reader_qos="status_in"),
    "diameter": Topic("diameter", "float64", "latched"),
    "diameter_centroid": Topic("diameter/centroid", "float64", "latched"),
    "diameter_rotation": Topic("diameter/rotation", "float64", "latched"),
    # whether matching is guaranteed, and by when (core.certificate): granted once, latched
    "certificate": Topic("certificate", "diagnostic_status", "latched"),
    "markers": Topic("markers", "markers", "markers"),
    "diagnostics": Topic("/diagnostics", "diagnostics", "diagnostics"),
}

#: the run's own messages (polymatch_interfaces/msg) by topic kind
OWN_MESSAGES = {
    "state": "AgentState",
    "state_block": "AgentStateBlock",
    "stage": "StageRows",
    "control": "ControlCommand",
    "record": "RunRecord",
}
#: standard messages by topic kind: (package, message)
STANDARD_MESSAGES = {
    "float64": ("std_msgs", "Float64"),
    "markers": ("visualization_msgs", "MarkerArray"),
    "diagnostic_status": ("diagnostic_msgs", "DiagnosticStatus"),
    "diagnostics": ("diagnostic_msgs", "DiagnosticArray"),
}


def message_type(kind: str, dim: int | None = None) -> type:
    """The message class of a topic kind; the one d <= 3 / d >= 4 switch of poses and twists."""
    import importlib

    if kind in ("pose", "twist"):
        if dim is not None and dim <= 3:
            from geometry_msgs.msg import PoseStamped, TwistStamped

            return PoseStamped if kind == "pose" else TwistStamped
        from polymatch_interfaces.msg import PoseNd, TwistNd

        return PoseNd if kind == "pose" else TwistNd
    if kind in OWN_MESSAGES:
        return getattr(importlib.import_module("polymatch_interfaces.msg"), OWN_MESSAGES[kind])
    package, name = STANDARD_MESSAGES[kind]
    return getattr(importlib.import_module(f"{package}.msg"), name)


def topic_name(key: str, agent: int | None = None) -> str:
    """The relative (or, for /diagnostics, absolute) name of a topic of the table."""
    name = TOPICS[key].name
    return name.format(agent=agent) if "{agent}" in name else name


def full_name(ensemble: str, key: str, agent: int | None = None) -> str:
    """The name as resolved in namespace /<ensemble> (without remaps): what users see."""
    name = topic_name(key, agent)
    return name if name.startswith("/") else f"/{ensemble.strip('/')}/{name}"


def namespace(ensemble: str) -> str:
    return "/" + ensemble.strip("/")


def _resolve(node: Node, name: str, resolver: Node | None) -> str:
    """Names for a node that does not share the process's remap rules: resolved by ``resolver``."""
    return name if resolver is None else resolver.resolve_topic_name(name)


def _per_agent_events(agent: int | None, kwargs: dict[str, Any], kind: str) -> None:
    """A per-agent topic gets no QoS event handlers unless asked (``event_callbacks``).

    rclpy gives every publisher and subscription default event handlers (incompatible QoS
    and type warnings), each a waitable that every spin of the node's executor walks through,
    with a list-membership test per waitable: a process hosting 256 agents (six per-agent
    topics each) spent a large share of its time there, and the runner, reading 1024 agents'
    final states, more (py-spy, 1024 agents in 4 processes).  A process's own topics keep them."""
    if agent is None or "event_callbacks" in kwargs:
        return
    from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks

    events = PublisherEventCallbacks if kind == "publisher" else SubscriptionEventCallbacks
    kwargs["event_callbacks"] = events(use_default_callbacks=False)


def publisher(node: Node, key: str, dim: int | None = None, agent: int | None = None,
              resolver: Node | None = None, **kwargs: Any) -> Publisher:
    t = TOPICS[key]
    _per_agent_events(agent, kwargs, "publisher")
    return node.create_publisher(
        message_type(t.kind, dim),
        _resolve(node, topic_name(key, agent), resolver),
        qos_profiles()[t.qos],
        **kwargs,
    )


def subscription(node: Node, key: str, callback: Callable[..., None], dim: int | None = None,
                 agent: int | None = None, mode: str = Mode.LOCKSTEP, resolver: Node | None = None,
                 **kwargs: Any) -> Subscription:
    t = TOPICS[key]
    _per_agent_events(agent, kwargs, "subscription")
    qos = t.reader_qos or (t.realtime_reader_qos if Mode(mode).ticks else None) or t.qos
    return node.create_subscription(
        message_type(t.kind, dim),
        _resolve(node, topic_name(key, agent), resolver),
        callback,
        qos_profiles()[qos],
        **kwargs,
    )


# QoS of each kind of topic: (history depth, None = keep all), reliable, latched
QOS = {
    # every lockstep stage must arrive.  VOLATILE: agents start only once their writers have
    # matched every expected reader (TRANSIENT_LOCAL halves the round rate here)
    "stage": (16, True, False),
    # stage readers keep every sample: a flood on a peer's topic can then never evict the
    # peer's real message before it is taken (it only blocks the flooding writer)
    "stage_in": (None, True, False),
    # poses: the monitor must see every lockstep pose; echo and RViz match RELIABLE/VOLATILE
    "pose": (100, True, False),
    # realtime peers: only the newest pose matters; a deeper queue would feed stale poses.
    # BEST_EFFORT (as sensor data): a lost pose is replaced by the next one, whereas a
    # RELIABLE reader holds every later pose back until the lost one is repaired (seconds
    # on a loaded machine, where loopback UDP drops datagrams)
    "latest": (1, False, False),
    # headline values: a late `ros2 topic echo` still gets the last one
    "latched": (1, True, True),
    # run records: each writer keeps its last (latched); one reader's history holds every
    # writer's (a topic without keys is one instance: depth is shared by all writers)
    "status": (1, True, True),
    "status_in": (1000, True, True),
    # the runner's reader of final states keeps every sample (as stage_in): a flood of another
    # writer on the topic then cannot evict the agent's own final state before it is taken
    "final_in": (None, True, True),
    # commands are not replayed to agents that join later (a restarted agent must not stop)
    "control": (10, True, False),
    "markers": (10, True, False),
    "diagnostics": (10, True, False),
}


def profile(depth: int | None, reliable: bool, latched: bool) -> QoSProfile:
    """The rclpy QoSProfile: keep the last ``depth`` (None: keep all), reliable or best effort,
    transient local (latched) or volatile (rclpy imported lazily: only needed here)."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    history: dict[str, Any] = {"history": HistoryPolicy.KEEP_ALL}
    if depth is not None:
        history = {"history": HistoryPolicy.KEEP_LAST, "depth": depth}
    return QoSProfile(
        **history,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
    )


def matching_profile(offered: Sequence[QoSProfile], depth: int) -> QoSProfile:
    """A reader's profile that every writer offering ``offered`` matches: reliable only if all
    of them are, latched only if all are (so it takes a latched topic's last value)."""
    from rclpy.qos import DurabilityPolicy, ReliabilityPolicy

    return profile(depth, all(p.reliability == ReliabilityPolicy.RELIABLE for p in offered),
                   all(p.durability == DurabilityPolicy.TRANSIENT_LOCAL for p in offered))


def qos_profiles() -> dict[str, QoSProfile]:
    """The rclpy QoSProfile of each entry of ``QOS``."""
    return {kind: profile(*spec) for kind, spec in QOS.items()}
