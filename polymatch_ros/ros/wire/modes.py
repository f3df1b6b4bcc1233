"""The run's three modes, and what differs between them, said once.

    lockstep  the agents exchange every stage of every step in rounds; every process is at the
              same step, so the run equals the centralised one to round-off; the step is the
              scene's dt, the run's simulated time is /clock, a pause holds every process at one
              step, and the summary compares the run with the centralised one
    realtime  each agent ticks on the wall clock (step = time_scale / rate) with the latest
              state it holds of each peer; runtime parameters (kappa, gamma, rate, limits) may
              change while it runs
    bridge    realtime agents that drive robots: each reads its robot's measured pose and sends
              it the model's command; a process per agent

A node or the supervisor holds a ``Mode`` (a ``str``: it is its own ROS parameter value) and
asks it what it needs, never compares mode names.
"""

from __future__ import annotations

from enum import StrEnum

from ...core.errors import ParameterError


class Mode(StrEnum):
    LOCKSTEP = "lockstep"
    REALTIME = "realtime"
    BRIDGE = "bridge"

    @property
    def exact(self) -> bool:
        """Stages in rounds, every process at one step: equal to the centralised run."""
        return self is Mode.LOCKSTEP

    @property
    def ticks(self) -> bool:
        """Steps on the wall clock (step = time_scale / rate), with runtime parameters."""
        return self is not Mode.LOCKSTEP

    @property
    def drives_robots(self) -> bool:
        """Agents read their robots' poses and command them (``ros/agents/bridge.py``)."""
        return self is Mode.BRIDGE

    @property
    def packs(self) -> bool:
        """A process may host several agents, exchanging one block of states a step or tick;
        the default packing is the measured one (``supervisor/packing.py``)."""
        return self is not Mode.BRIDGE

    def tick_step(self, rate: float, time_scale: float) -> float:
        """Simulated seconds a tick: realtime runs time_scale x faster than the wall clock,
        a bridge's robots move in real time (lockstep steps the scene's dt: no tick)."""
        return time_scale / rate if self is Mode.REALTIME else 1.0 / rate

    @property
    def monitored_as(self) -> Mode:
        """How the monitor follows the run: step by step (lockstep) or by the latest states."""
        return Mode.LOCKSTEP if self.exact else Mode.REALTIME


#: the mode names, as ``--mode`` and the ``mode`` parameter take them
MODES: tuple[str, ...] = tuple(m.value for m in Mode)
#: the monitor's ``mode`` parameter: how it follows the run (``Mode.monitored_as``)
MONITOR_MODES: tuple[str, ...] = tuple(dict.fromkeys(m.monitored_as.value for m in Mode))
#: the modes whose processes exchange blocks of states (``Mode.packs``)
BLOCK_MODES: tuple[str, ...] = tuple(m.value for m in Mode if m.packs)


def mode_of(text: str) -> Mode:
    """The mode named ``text``; a ParameterError in one line for another name."""
    try:
        return Mode(text)
    except ValueError:
        raise ParameterError(f"mode: {text!r} is not one of {', '.join(MODES)}") from None
