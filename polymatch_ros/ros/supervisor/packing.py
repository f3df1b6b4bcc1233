"""How many agents each process hosts: ``-k`` as asked, else what was measured fastest.

Lockstep (``python -m benchmarks packing`` and ``scaling``, ``docs/bench/``, 2 cores): a round
costs each process its share of the numerics plus one DDS exchange with every other process,
and the exchange dominates; one process was the fastest packing at 8, 32, 64, 256 and 1024
agents (``docs/bench/packing.md``), and at 4096 (``docs/bench/scaling.md``).

Realtime (``python -m benchmarks realtime_scale``, ``docs/bench/realtime_scale.md``): a tick
costs each process its agents' numerics, vectorised, plus reading the other processes' states
and publishing its own, and the reading dominates: one process holds the rate with the least
CPU a tick at every size measured, and is the default as in lockstep; ``-k 1`` keeps one agent
a process, so that a crash costs one agent.  A host that runs only some of the agents
(``--only``) keeps a process per agent by default: the other agents may be of another
implementation, which speaks the public per-agent state topics (``agent_<i>/state``), not the
blocks.  Bridge runs relay one robot a process.

Every agent is its own node at any packing (``agents.hosted``): a full node (its services and
parameters too) while a process hosts up to ``FULL_AGENT_NODES`` agents, a lean one (its pose
topics) beyond, where the full nodes' endpoints would make a process's start-up take many
times as long (``python -m benchmarks packing``: the agent-node table).
"""

from __future__ import annotations

from dataclasses import dataclass

from ...core.errors import PolymatchError
from ..wire.modes import Mode

# rmw_fastrtps, under ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST, probes the first 32 participant
# ports on 127.0.0.1 (its UDP maxInitialPeersRange): two participants beyond that never meet.
LOCALHOST_PARTICIPANTS = 32

#: lockstep: the most agents one process hosts unless -k says otherwise (measured, above)
LOCKSTEP_AGENTS_PER_PROCESS = 4096
#: realtime: the most agents one process hosts unless -k says otherwise (measured, above)
REALTIME_AGENTS_PER_PROCESS = 4096
#: --agent-nodes auto: full agent nodes in a process of up to this many agents, lean beyond
FULL_AGENT_NODES = 32


@dataclass(frozen=True)
class PackingAsked:
    """What decides the agents per process: -k as asked and this host's own participants."""

    requested: int | None      # -k; None: the mode's default (``choose_packing``)
    monitor: bool              # the monitor is one more participant on this host
    recorder: bool = False     # --record: the recorder is one more
    mode: Mode = Mode.LOCKSTEP
    agent_nodes: str = "auto"  # --agent-nodes as asked
    whole: bool = True         # this host runs every agent (no --only): realtime may pack

    def __post_init__(self) -> None:
        object.__setattr__(self, "mode", Mode(self.mode))  # a mode's name is taken too


@dataclass(frozen=True)
class Packing:
    """Agents per process for this host, and why (the run's first line says it): decided once,
    with the run's plan (``plan.build_run_plan``)."""

    agents_per_process: int
    reason: str
    agent_nodes: str = "none"  # what a packed process gives each agent: full | lean | none


def fewest_agents_per_process(n_agents: int, own: int) -> int:
    """Agents per process that keep ``own`` + the agent processes within LOCALHOST_PARTICIPANTS."""
    return -(-n_agents // (LOCALHOST_PARTICIPANTS - own))


def choose_packing(packing: PackingAsked, n_agents: int, localhost: bool) -> Packing:
    """-k as given (checked against the participant limit); else the measured rule of lockstep
    and of realtime (the whole run on this host), or one process per agent (bridge; realtime
    with ``--only``) while the processes fit; with the agent nodes for that packing
    (``agent_nodes``)."""
    choice = _agents_per_process(packing, n_agents, localhost)
    k = choice.agents_per_process
    return Packing(k, choice.reason, agent_nodes(packing.agent_nodes, min(k, n_agents)))


def agent_nodes(asked: str, k: int) -> str:
    """What each agent of a process hosting ``k`` gets: as asked, or by ``FULL_AGENT_NODES``
    (``auto``); a process of one agent is the agent's node itself ("none")."""
    if k < 2:
        return "none"
    if asked != "auto":
        return asked
    return "full" if k <= FULL_AGENT_NODES else "lean"


def _agents_per_process(packing: PackingAsked, n_agents: int, localhost: bool) -> Packing:
    own = 1 + int(packing.monitor) + int(packing.recorder)  # the runner, monitor, recorder
    need = fewest_agents_per_process(n_agents, own) if localhost else 1
    if packing.requested is not None:
        procs = -(-n_agents // packing.requested)
        if localhost and procs + own > LOCALHOST_PARTICIPANTS:
            raise PolymatchError(
                f"{procs} agent processes + {own} own = {procs + own} DDS participants, but "
                f"LOCALHOST discovery reaches {LOCALHOST_PARTICIPANTS} per domain (rmw_fastrtps' "
                f"initial-peer range); use -k {need} or more"
            )
        return Packing(packing.requested, f"-k {packing.requested} as asked")
    if packing.mode.exact:
        k = max(need, min(n_agents, LOCKSTEP_AGENTS_PER_PROCESS))
        return Packing(k, f"lockstep's fastest measured packing, up to "
                                f"{LOCKSTEP_AGENTS_PER_PROCESS} agents a process "
                                f"(docs/bench/packing.md); -k 1: a process per agent")
    if packing.mode.packs and packing.whole:
        k = max(need, min(n_agents, REALTIME_AGENTS_PER_PROCESS))
        return Packing(k, f"realtime's measured packing: the least CPU a tick, up to "
                                f"{REALTIME_AGENTS_PER_PROCESS} agents a process "
                                f"(docs/bench/realtime_scale.md); -k 1: a process per agent, "
                                f"so that a crash costs one agent")
    if need > 1:
        return Packing(need, f"{n_agents} agents + {own} own processes exceed the "
                                   f"{LOCALHOST_PARTICIPANTS} DDS participants LOCALHOST "
                                   f"discovery reaches: the fewest agents a process that fit")
    why = "" if packing.whole else ", and other hosts' agents read agent_<i>/state (--only)"
    return Packing(1, f"{packing.mode}: a process per agent, so that a crash costs one "
                            f"agent{why}")
