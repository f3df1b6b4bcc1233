"""Parameters changed while an agent runs (``ros2 param set``): checked now, applied next tick.

In realtime and bridge modes ``params.RUNTIME`` (kappa, gamma, mass, rate, speed and
acceleration limits) may be set while running: a value is checked against its range
(``params.check_value``) and the gains against the model (``params.check_gains``: gamma > 0
for (A-2), ...) in the set callback - a bad one is rejected with the reason - and applied at
the agent's next tick, so a tick never mixes old and new gains.  The parameter then reads the
new value.  Every other parameter, and all of them in lockstep, are declared read-only.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import replace
from typing import TYPE_CHECKING, Any

from ...core.errors import ParameterError
from ..wire.modes import Mode
from .configs import AgentConfig, config_values
from .params import AGENT, GAINS, RUNTIME, check_gains, check_value

if TYPE_CHECKING:
    from rclpy.impl.rcutils_logger import RcutilsLogger
    from rclpy.node import Node
    from rclpy.parameter import Parameter

    from ...core.model import Model, State
    from ...core.scenes.scene import Scene

SPEC = {p.name: p for p in AGENT}
GAINS_SET = frozenset(GAINS)


def gains(model: Model, config: AgentConfig) -> Model:
    """``model`` with the kappa, gamma and mass parameters of (A-1)/(A-2) (the parameters hold
    the scene's values unless given; a first-order model has no mass parameter)."""
    given = {k: getattr(config, k) for k in GAINS}
    return replace(model, **{k: v for k, v in given.items() if v is not None})


def validate(changes: Iterable[Parameter]) -> tuple[dict[str, Any] | None, str | None]:
    """(accepted {name: value}, None) or (None, reason) for rclpy ``Parameter``-like changes."""
    accepted = {}
    for param in changes:
        if param.name not in RUNTIME:
            return None, f"parameter {param.name!r} is read-only while running"
        try:
            accepted[param.name] = check_value(SPEC[param.name], param.value)
        except ParameterError as exc:
            return None, str(exc)
    return accepted, None


class RuntimeParams:
    """Mixin of realtime and bridge agents: ``watch_parameters()`` once, ``apply_runtime()``
    each tick (True when something changed; ``self.config`` then holds the new values)."""

    # what the agent (``agent_base.AgentBase``) it is mixed into provides
    node: Node
    log: RcutilsLogger
    scene: Scene
    model: Model
    config: AgentConfig
    mode: Mode
    state: State
    pending: dict[str, Any]

    def watch_parameters(self) -> None:
        """Take kappa and gamma from the parameters, then accept changes while running."""
        self.pending = {}
        self.model = gains(self.scene.model, self.config)
        self.rebuild_system()
        self.node.add_on_set_parameters_callback(self._on_set)

    def _on_set(self, changes: list[Parameter]) -> Any:
        from rcl_interfaces.msg import SetParametersResult

        # a parameter the node declares while running (``start_time``) is not a change
        changes = [c for c in changes if self.node.has_parameter(c.name)]
        accepted, reason = validate(changes)
        if accepted is not None and GAINS_SET & set(accepted):
            try:
                check_gains(self.scene.model, self.mode,
                            {**config_values(self.config), **self.pending, **accepted})
            except ParameterError as exc:
                accepted, reason = None, str(exc)
        if accepted is None:
            self.log.warning(f"parameter change rejected: {reason}")
            return SetParametersResult(successful=False, reason=reason)
        self.pending.update(accepted)
        return SetParametersResult(successful=True)

    def apply_runtime(self) -> bool:
        """Apply the accepted changes (next tick); rebuild the model when the gains changed."""
        if not getattr(self, "pending", None):
            return False
        changed, self.pending = self.pending, {}
        old = {k: self._in_use(k) for k in changed}
        self.config = replace(self.config, **changed)
        if GAINS_SET & set(changed):
            self.model = gains(self.scene.model, self.config)
            self.rebuild_system()
        described = ", ".join(f"{k} {old[k]:g} -> {self._in_use(k):g}" for k in changed)
        self.log.info(f"parameters applied at t = {self.state.t:.4g}: {described}")
        return True

    def _in_use(self, name: str) -> Any:
        """The value in use: the model's gains, else the parameter."""
        return getattr(self.model if name in GAINS else self.config, name)

    def rebuild_system(self) -> None:
        raise NotImplementedError

    def diagnostic_note(self) -> tuple[str, dict[str, Any]]:
        """The gains in use and the runtime parameters, for the diagnostics."""
        extra = {"kappa": float(self.model.kappa), "gamma": float(self.model.gamma)}
        if self.model.order == 2:
            extra["mass"] = float(self.model.mass)
        extra.update({k: getattr(self.config, k) for k in RUNTIME
                      if k not in extra and k not in GAINS})
        return "", extra
