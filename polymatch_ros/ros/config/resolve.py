"""What a node makes of the configuration it was given: the scene file read (once: the scene
and, for an agent, its numerical plan travel on with the configuration), the values it takes
from the scene unless given, and the one-line errors of what does not fit together.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

from ...core.errors import ParameterError
from ..wire.modes import Mode, mode_of
from .configs import AgentConfig, MonitorConfig, RobotConfig
from .params import GAINS, check_gains

if TYPE_CHECKING:
    from ...core.scenes.scene import Scene
    from ...core.stepping.simulate import NumericalPlan


def scene_file(name: str | None) -> str:
    """The scene file a 'scene' parameter names (a path, or a shipped scene's name)."""
    from ...core.scenes.scene import resolve_scene_path

    if not name:
        raise ParameterError("parameter 'scene' is required (a scene file)")
    return os.path.abspath(resolve_scene_path(name))


def _load(config: AgentConfig | MonitorConfig) -> tuple[str, Scene]:
    """(the scene file, the scene) of a configuration, its end time applied when given."""
    from ...core.scenes.scene import load_scene

    path = scene_file(config.scene)
    return path, load_scene(path, {"time.t_end": config.t_end})


def resolve_monitor(config: MonitorConfig) -> tuple[MonitorConfig, Scene]:
    """The monitor's configuration (the scene file read, its end time unless given) and the
    scene it loaded."""
    path, scene = _load(config)
    return replace(config, scene=path, t_end=scene.t_end), scene


def resolve_robot(config: RobotConfig) -> RobotConfig:
    """The robot's configuration: the scene file read, the noise seed 1000 + agent unless
    given."""
    seed = 1000 + config.agent if config.seed is None else config.seed
    return replace(config, scene=scene_file(config.scene), seed=seed)


@dataclass(frozen=True)
class ResolvedAgent:
    """An agent process's configuration as it runs, with what resolving it loaded: the scene
    (its own model; the gains in use are the configuration's) and the numerical plan."""

    config: AgentConfig
    scene: Scene
    numerics: NumericalPlan


def resolve_agent(config: AgentConfig) -> ResolvedAgent:
    """The agent's configuration: the scene file read, its end time, gains, integrator and step
    unless given, the agents this process hosts, how it starts; ParameterError for a parameter
    given that the mode does not take, or for gains the model cannot run with."""
    from ...core.stepping.simulate import choose_numerics

    mode = mode_of(config.mode)
    lockstep = mode.exact
    _refuse_outside_mode(config, mode)
    path, scene = _load(config)
    model = check_gains(scene.model, mode, {} if lockstep else
                        {k: getattr(config, k) for k in GAINS})
    config = replace(config, scene=path, t_end=scene.t_end, kappa=model.kappa, gamma=model.gamma,
                     mass=model.mass if model.order == 2 else None,
                     **_hosted(config.agent, config.agents))
    step = config.dt if lockstep else mode.tick_step(config.rate, config.time_scale)
    numerics = choose_numerics(replace(scene, model=model), config.integrator, step,
                               distributed=True)
    config = replace(config, integrator=numerics.name, dt=numerics.dt if lockstep else None,
                     **(_start(config.start, config.start_time) if not lockstep
                        else dict(start=None)))
    return ResolvedAgent(config, scene, numerics)


def _refuse_outside_mode(config: AgentConfig, mode: Mode) -> None:
    """ParameterError for a given parameter that ``mode`` does not take."""
    if mode.exact:
        names = [k for k in (*GAINS, "start", "start_time") if getattr(config, k) is not None]
        why = ("realtime and bridge only (lockstep runs the scene's model, to equal the "
               "centralised simulation, and starts once every peer is matched)")
    else:
        names = ["dt"] if config.dt is not None else []
        why = "lockstep only (" + ("a realtime agent steps time_scale/rate simulated seconds a "
                                   "tick" if not mode.drives_robots else "a bridge agent takes no "
                                   "step: its robot moves") + ")"
    if names:
        plural = "s" if len(names) > 1 else ""
        raise ParameterError(f"parameter{plural} {', '.join(map(repr, names))}: {why}")


def _hosted(agent: int | None, agents: list[int] | None) -> dict[str, Any]:
    """'agent' and 'agents' of a process: given either, or both when they agree."""
    if not agents:
        agents = [0 if agent is None else agent]
    elif agent is not None and agent != agents[0]:
        raise ParameterError(f"parameters 'agent', 'agents': agent {agent} is not the first of "
                             f"agents {agents}")
    return {"agent": agents[0], "agents": list(agents)}


def _start(start: str | None, at: float | None) -> dict[str, Any]:
    """'start' and 'start_time': at the given time, else now unless given otherwise."""
    start = start or ("at" if at is not None else "now")
    if start == "at" and at is None:
        raise ParameterError("parameter 'start': at needs 'start_time' (the epoch of t = 0)")
    if start != "at" and at is not None:
        raise ParameterError(f"parameter 'start_time': a time of t = 0 with start {start}; "
                             "give start:=at (or leave 'start' out)")
    return {"start": start, "start_time": at}
