"""The runner's own small node: progress, the ensemble's services, the agents' final poses, the
graph check."""

from __future__ import annotations

import math
import time
from collections import Counter
from collections.abc import Callable, Collection, Sequence
from typing import TYPE_CHECKING, Any

from ...core.errors import PolymatchError
from ...core.model import State
from .. import wire
from ..wire.control import ControlClient, command_message, parse_command
from ..wire.intake import LeanReaders

if TYPE_CHECKING:
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node

    from ...core.model import Model
    from ...core.scenes.scene import Scene
    from .lifecycle_driver import LifecycleDriver


#: how often the runner takes the agents' latched final states (s): once an agent process says
#: it has finished, and before that (a final state can come first, or from a silent process)
FINALS_PERIOD = 0.2
FINALS_IDLE_PERIOD = 2.0


class Watcher:
    """Lives in the ensemble's namespace (``/<ensemble>/runner``; ``runner_<first agent>`` on
    a host that runs some of the agents).

    It hears every process's run record (``status``: progress, agents up, and the monitor's
    headline diameter), calls the ensemble's start and stop services (``control``), and takes each
    agent's *final* state from its latched ``final_state`` topic (packed lockstep processes:
    its block's ``final_state_block``) for the summary - not
    the per-step poses, so supervising a run adds no load to the lockstep rounds.  Only this
    run's final states and run records are taken (``run_id``, ``wire.exchange``): a latched
    final pose or a record of another run, or anything else on the topics, is ignored and
    counted (``ignored``), so it can neither stop this run early nor change its result.
    """

    node: Node
    executor: SingleThreadedExecutor
    scene: Scene
    model: Model
    grp: Any                                        # the scene's rotation group
    monitor: wire.RunRecord | None                  # the monitor's latest run record
    agents: dict[tuple[int, ...], wire.RunRecord]   # agents of a process -> its latest record
    poses: dict[int, tuple[float, wire.Row]]        # agent -> (t, final pose)
    velocities: dict[int, tuple[Any, Any]]          # agent -> (v, w) of its final twist
    control: Any                                    # publisher of the 'received' handshake
    services: ControlClient
    ensemble_control: Any                           # the services, when no monitor runs
    stop_requested_at: float | None                 # ensemble time of a stop not the runner's
    stop_sent: bool                                 # the runner called the stop service

    def __init__(self, scene: Scene, ensemble: str, name: str = "runner",
                 run_id: int = 0, blocks_of: int | None = None) -> None:
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.node import Node

        self.node = Node(name, namespace=wire.namespace(ensemble))
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)
        self.scene, self.model, self.run_id = scene, scene.model, int(run_id)
        self.ignored = 0  # run records of another run, or not records at all
        self.final_drops: Counter[str] = Counter()  # final states dropped, by reason
        self.grp = self.model.rotations
        self.monitor = None  # the monitor's latest run record
        self.last_known_time: float | None = None  # ``ensemble_time``'s last answer
        self.agents = {}  # agents tuple -> latest run record of that process
        self.poses, self.velocities = {}, {}
        node, dim = self.node, self.model.dim
        wire.subscription(node, "status", self._status)
        self.control = wire.publisher(node, "control")  # the 'received' handshake
        self.stop_requested_at, self.stop_sent = None, False
        wire.subscription(node, "control", self._control)  # a stop someone else asked for
        self.services = ControlClient(node)  # start and stop: the ensemble's services
        # The final states on a lean node of their own, taken a few times a second: an rclpy
        # spin rebuilds its wait set from every reader, and 1024 of them made the spins of the
        # runner's loop its main cost (py-spy, 1024 agents in 4 processes).  Packed
        # lockstep processes (K = ``blocks_of``) send them a block at a time: with a reader per
        # agent the runner missed final states at 4096 agents.
        self.finals = LeanReaders(node, "_finals")
        self._finals_taken_at = -math.inf
        if blocks_of is not None:
            for b in range(-(-self.model.n_agents // blocks_of)):
                self.finals.subscribe("final_state_block", self._final_block(b, blocks_of),
                                      dim, b, wire.Mode.LOCKSTEP)
        else:
            for a in range(self.model.n_agents):
                self.finals.subscribe("final_state", self._final(a), dim, a,
                                      wire.Mode.LOCKSTEP)

    def _control(self, msg: Any) -> None:
        """A 'stop' on the control topic that the runner did not send: the ensemble's stop
        service, called from outside (``ros2 service call /polymatch/stop ...``)."""
        command = parse_command(msg)
        if command is None or command[0] != "stop" or self.stop_sent:
            return
        if self.stop_requested_at is None:
            self.stop_requested_at = self.time_every_agent_reached()

    def _status(self, msg: Any) -> None:
        rec = wire.RunRecord.from_msg(msg)
        if rec is None or rec.run_id != self.run_id:
            self.ignored += 1
            return
        if rec.role == "monitor":
            self.monitor = rec
            return
        old = self.agents.get(rec.agents)
        # a process's steps never fall: fewer is a new process of these agents (restarted, or
        # a host's run started again), whose record replaces the dead one's
        if old is None or rec.t >= old.t or rec.steps < old.steps:
            self.agents[rec.agents] = rec

    @property
    def diameter(self) -> float | None:
        """The headline diameter of the monitor's latest run record (None before one)."""
        return None if self.monitor is None else self.monitor.diameter

    def _final(self, agent: int) -> Callable[[Any, Any], None]:
        """The callback of one agent's final state: its pose and, in second order, its
        velocities, if the message is this run's and well formed."""

        def receive(msg: Any, _info: Any) -> None:
            got, reason = wire.decode_exchange(msg, self.grp, self.model.dim, self.run_id,
                                               agent, self.scene.t_end)
            if got is None:
                self.final_drops[reason or "malformed"] += 1
                return
            self._take_final(agent, got)

        return receive

    def _final_block(self, block: int, k: int) -> Callable[[Any, Any], None]:
        """The callback of one block's final states (``wire.decode_exchange_block``)."""

        def receive(msg: Any, _info: Any) -> None:
            got, reason = wire.decode_exchange_block(msg, self.grp, self.model.dim, self.run_id,
                                                     block, k, self.scene.t_end)
            if got is None:
                self.final_drops[reason or "malformed"] += 1
                return
            for agent, motion in got:
                self._take_final(agent, motion)

        return receive

    def _take_final(self, agent: int, got: wire.Motion) -> None:
        """An agent's final pose and, in second order, its velocities."""
        self.poses[agent] = (got.t, wire.Row(got.x, got.rot))
        if self.model.order == 2 and got.v is not None and got.w is not None:
            self.velocities[agent] = (got.v, got.w)

    def spin(self, timeout: float) -> None:
        """Serve the runner's node for up to ``timeout`` s, and take the agents' final states
        that have come: every ``FINALS_PERIOD`` s once an agent process has finished, every
        ``FINALS_IDLE_PERIOD`` s before; each take reads all that the readers hold."""
        self.executor.spin_once(timeout_sec=timeout)
        now = time.monotonic()
        ending = any(rec.finished for rec in self.agents.values())
        if now - self._finals_taken_at >= (FINALS_PERIOD if ending else FINALS_IDLE_PERIOD):
            self._finals_taken_at = now
            # all a reader holds: the readers keep every sample (``final_in``), so another
            # writer flooding an agent's topic queues ahead of the agent's own final state; a
            # take of a few a reader would fall ever further behind and never reach it
            self.finals.drain()

    def agent_time(self) -> dict[int, float]:
        """{agent: simulated time} from the agents' run records."""
        return {a: rec.t for agents, rec in self.agents.items() for a in agents}

    def agents_up(self) -> bool:
        return len(self.agent_time()) >= self.model.n_agents

    def ensemble_time(self) -> float | None:
        """Simulated time of the ensemble: the monitor's last report, else the slowest agent's;
        while neither is known (a monitor and an agent restarting), the last time known."""
        if self.monitor is not None:
            self.last_known_time = self.monitor.t
        else:
            times = self.agent_time()
            if len(times) >= self.model.n_agents:
                self.last_known_time = min(times.values())
        return self.last_known_time

    def time_every_agent_reached(self) -> float:
        """The latest simulated time every agent is known to have reached: the later of the
        monitor's last report and the slowest agent's last run record.  Either can be the
        staler one (the monitor reports at its rate, each agent once a second), so a stop
        called once every agent's record said t was dated before t by the monitor's alone."""
        times = self.agent_time()
        slowest = min(times.values()) if len(times) >= self.model.n_agents else None
        known = [t for t in (self.ensemble_time(), slowest) if t is not None]
        return max(known, default=min(times.values(), default=0.0))

    def all_heard(self) -> bool:
        """The monitor's last report covered every agent."""
        return self.monitor is not None and self.monitor.agents_heard >= self.model.n_agents

    def refuse_names_in_use(self, names: Sequence[str], seconds: float) -> None:
        """Before this run starts a process: listen ``seconds`` for the ROS graph and refuse,
        in one line, if a node of ``names`` (this host's runner, agents, monitor) already runs
        in the ensemble's namespace - another ensemble of the same name in this domain, whose
        topics this run's agents would share."""
        ns = self.node.get_namespace()
        deadline = time.monotonic() + seconds
        while True:
            others = self._ensemble_nodes()
            if self.node.get_name() in others:
                others.remove(self.node.get_name())  # this runner itself, once
            taken = sorted(set(others) & set(names))
            if taken:
                raise PolymatchError(
                    f"an ensemble named {ns.strip('/')!r} already runs in this ROS domain "
                    f"(its nodes {', '.join(ns + '/' + n for n in taken[:3])}); nothing started: "
                    f"use --ensemble NAME or another ROS_DOMAIN_ID"
                )
            if time.monotonic() > deadline:
                return
            self.spin(0.05)

    def _ensemble_nodes(self) -> list[str]:
        """The names of the nodes in the ensemble's namespace, as the graph lists them (a name
        twice if two nodes take it)."""
        ns = self.node.get_namespace()
        return [n for n, space in self.node.get_node_names_and_namespaces() if space == ns]

    def check_graph(self, names: Sequence[str], restarted: Collection[str] = ()) -> bool:
        """Every node of ``names`` is in the ensemble's namespace, and no name is taken twice
        (but those of ``restarted`` processes: a dead process's node stays in the graph until
        its DDS lease runs out)."""
        ns = self.node.get_namespace()
        found = self._ensemble_nodes()
        twice = sorted({n for n in found if found.count(n) > 1} - set(restarted))
        if twice:
            raise PolymatchError(
                f"node name {ns}/{twice[0]} is taken twice: another ensemble named "
                f"{ns.strip('/')!r} runs in this ROS domain (use --ensemble)"
            )
        return not set(names) - set(found)

    def pose_times(self) -> dict[int, float]:
        """Simulated time of every agent's final pose."""
        return {a: p[0] for a, p in self.poses.items()}

    def have_final(self) -> bool:
        return len(self.poses) >= self.model.n_agents and (
            self.model.order == 1 or len(self.velocities) >= self.model.n_agents
        )

    def have_final_of(self, agents: Sequence[int]) -> bool:
        """The final states of ``agents`` (poses and, in second order, velocities) are here."""
        return all(
            a in self.poses and (self.model.order == 1 or a in self.velocities) for a in agents
        )

    def monitor_reported_final(self) -> bool:
        """The monitor's last report is of the final poses' step, with every agent heard."""
        times = self.pose_times()
        return (
            self.monitor is not None
            and bool(times)
            and self.monitor.agents_heard >= self.model.n_agents
            and self.monitor.t >= max(times.values()) - 1e-9
        )

    def stop(self) -> bool:
        """The ensemble's ``stop`` service; False while it is not up yet."""
        self.stop_sent = True
        return self.services.call("stop")

    def received(self) -> None:
        """'received' on the control topic: every final pose is here (runs across hosts)."""
        from rclpy.duration import Duration

        self.control.publish(command_message("received"))
        self.control.wait_for_all_acked(Duration(seconds=2.0))

    def start(self) -> bool:
        """The ensemble's ``start`` service; False while it is not up yet."""
        return self.services.call("start")

    def drive_lifecycle(self, names: Sequence[str],
                        last_words: Callable[[str], str]) -> LifecycleDriver:
        """A ``LifecycleDriver`` that configures and activates the agent nodes ``names``
        (``last_words(name)``: that process's last line, for the error of a refused
        transition)."""
        from .lifecycle_driver import LifecycleDriver

        return LifecycleDriver(self.node, self.node.get_namespace(), names, last_words)

    def host_ensemble_services(self, mode: wire.Mode) -> None:
        """On a host that runs every agent and no monitor: this node offers them."""
        from ..wire.control import EnsembleControl

        self.ensemble_control = EnsembleControl(self.node, mode)

    def final_state(self) -> State | None:
        """The final pose of every agent as a core State (None if some agent never reported)."""
        if len(self.poses) < self.model.n_agents:
            return None
        return wire.state_of(self.model, {a: p[1] for a, p in self.poses.items()},
                             min(p[0] for p in self.poses.values()), self.velocities)

    def destroy(self) -> None:
        self.finals.destroy()
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
