"""What one `polymatch run` does, decided before anything starts: the ``RunPlan``.

The command line (``polymatch_ros.cli.run``) builds it once and checks it (every bad option is
a one-line error before a process starts); the runner only reads it.  Values derived from the
scene or the mode (this host's agents, the lead flag, time scale 1 in bridge mode, the
noise-floor tolerance of bridge mode) are in it as decided, never patched in later.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from ..wire.modes import Mode
from .recovery import RestartPolicy

if TYPE_CHECKING:
    from ...core.scenes.scene import Scene
    from ...core.stepping.simulate import NumericalPlan
    from ..network.discovery import DiscoverySpec

@dataclass(frozen=True)
class Hosts:
    """Where the ensemble runs: its namespace, the agents of this host, discovery."""

    ensemble: str                      # namespace /<ensemble>
    agents: tuple[int, ...]            # the agents this host runs (--only; else all)
    monitor: bool                      # this host starts the monitor (not --no-monitor)
    lead: bool                         # this host runs the monitor or every agent
    discovery: DiscoverySpec           # how the DDS participants find each other
    agents_per_process: int | None     # -k as asked (bridge mode: 1); None: choose
    agent_nodes: str = "auto"          # --agent-nodes: auto | full | lean | none (``hosted``)
    isolated: bool = False             # --isolated: a fresh private domain, not the user's
    run_id: int | None = None          # --run-id: the id every message of the run carries;
                                       # None: chosen (``runner``)


@dataclass(frozen=True)
class Timing:
    """How long the run may take, and how the agents step and wait."""

    timeout: float         # wall-clock limit of the whole run (s)
    hold: float            # stop once the diameter stayed under tolerance this long (sim. s)
    rate: float            # realtime: steps per second
    time_scale: float      # realtime: simulated seconds per wall-clock second (bridge: 1)
    peer_timeout: float    # realtime: drop silent peers after this many s
    delay: float           # realtime: injected transport delay (s)
    round_timeout: float   # lockstep: a round fails after this many s if a peer has left


@dataclass(frozen=True)
class Outputs:
    """What the run prints and writes."""

    save: str | None       # npz of the final poses (checked writable, suffix appended)
    records: str | None    # every process's run record, JSON lines
    quiet: bool            # no progress, no first line
    verbose: bool          # every agent's final line
    compare: bool          # lockstep: compare with the centralised simulation
    record: str | None = None  # MCAP file of the run's topics (checked writable, suffix appended)
    logs: str | None = None    # a directory: each process's whole output in <name>.log


@dataclass(frozen=True)
class BridgeOptions:
    """The simulated robots of bridge mode and the agents' command limits."""

    lag: float
    position_noise: float
    angle_noise: float
    max_linear_speed: float
    max_angular_speed: float
    max_linear_accel: float
    max_angular_accel: float
    robot_log: str | None      # a directory for the robots' pose logs
    drive: str = "holonomic"   # holonomic | unicycle (differential-drive robots)
    cmd_vel_type: str = "twist_stamped"  # first order: the cmd_vel message (params.CMD_TYPES)


@dataclass(frozen=True)
class Packing:
    """What decides the agents per process: -k as asked and this host's own participants."""

    requested: int | None      # -k; None: the mode's default (``packing.choose_packing``)
    monitor: bool              # the monitor is one more participant on this host
    recorder: bool = False     # --record: the recorder is one more
    mode: Mode = Mode.LOCKSTEP
    agent_nodes: str = "auto"  # --agent-nodes as asked
    whole: bool = True         # this host runs every agent (no --only): realtime may pack

    def __post_init__(self) -> None:
        object.__setattr__(self, "mode", Mode(self.mode))  # a mode's name is taken too


@dataclass(frozen=True)
class RunPlan:
    """One `polymatch run`, checked: the scene, the numerical plan and every option."""

    scene_path: str            # the scene file (a shipped scene resolved)
    scene: Scene               # loaded, --t-end applied; bridge mode: noise-floor tolerance
    numerics: NumericalPlan             # the fixed-step integrator and its dt
    mode: Mode
    hosts: Hosts
    timing: Timing
    outputs: Outputs
    bridge: BridgeOptions | None = None   # bridge mode only
    on_failure: RestartPolicy = field(default_factory=RestartPolicy)  # --on-failure

    def __post_init__(self) -> None:
        object.__setattr__(self, "mode", Mode(self.mode))  # a mode's name is taken too

    @property
    def realtime(self) -> bool:
        """The agents step on the wall clock (realtime and bridge mode)."""
        return self.mode.ticks

    @property
    def n_agents(self) -> int:
        """Agents of the whole ensemble (on every host)."""
        return int(self.scene.model.n_agents)

    @property
    def every_agent_here(self) -> bool:
        """This host runs every agent of the ensemble."""
        return len(self.hosts.agents) == self.n_agents

    @property
    def packing(self) -> Packing:
        """What decides this host's agents per process."""
        return Packing(self.hosts.agents_per_process, self.hosts.monitor,
                       self.outputs.record is not None, self.mode, self.hosts.agent_nodes,
                       self.every_agent_here)
