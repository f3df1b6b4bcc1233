"""Parameters changed while an agent runs (``ros2 param set``): checked now, applied next tick.

In realtime and bridge modes ``params.RUNTIME`` (kappa, gamma, rate, speed and acceleration
limits) may be set while running: a value is checked against its range (``params.check_value``)
in the set callback - a bad one is rejected with the reason - and applied at the agent's next
tick, so a tick never mixes old and new gains.  Every other parameter, and all of them in
lockstep, are declared read-only.
"""

from dataclasses import replace

from ..core.errors import ParameterError
from .params import AGENT, RUNTIME, check_value

SPEC = {p.name: p for p in AGENT}


def gains(model, params):
    """``model`` with the kappa and gamma parameters (0 = the scene's value) of (A-1)/(A-2)."""
    kappa = params["kappa"] or model.kappa
    gamma = params["gamma"] or model.gamma
    return replace(model, kappa=kappa, gamma=gamma)


def validate(changes):
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
    each tick (True when something changed; ``self.params`` then holds the new values)."""

    def watch_parameters(self):
        """Take kappa and gamma from the parameters, then accept changes while running."""
        self.pending = {}
        self.model = gains(self.scene.model, self.params)
        self.rebuild_system()
        self.node.add_on_set_parameters_callback(self._on_set)

    def _on_set(self, changes):
        from rcl_interfaces.msg import SetParametersResult

        accepted, reason = validate(changes)
        if accepted is None:
            self.log.warning(f"parameter change rejected: {reason}")
            return SetParametersResult(successful=False, reason=reason)
        self.pending.update(accepted)
        return SetParametersResult(successful=True)

    def apply_runtime(self):
        """Apply the accepted changes (next tick); rebuild the model when the gains changed."""
        if not getattr(self, "pending", None):
            return False
        changed, self.pending = self.pending, {}
        old = {k: self._in_use(k) for k in changed}
        self.params.update(changed)
        if "kappa" in changed or "gamma" in changed:
            self.model = gains(self.scene.model, self.params)
            self.rebuild_system()
        described = ", ".join(f"{k} {old[k]:g} -> {self._in_use(k):g}" for k in changed)
        self.log.info(f"parameters applied at t = {self.state.t:.4g}: {described}")
        return True

    def _in_use(self, name):
        """The value in use: the model's gains (0 = the scene's), else the parameter."""
        return getattr(self.model, name) if name in ("kappa", "gamma") else self.params[name]

    def rebuild_system(self):
        raise NotImplementedError

    def diagnostic_note(self):
        """The gains in use and the runtime parameters, for the diagnostics."""
        extra = {"kappa": float(self.model.kappa), "gamma": float(self.model.gamma)}
        extra.update({k: self.params[k] for k in RUNTIME if k not in extra})
        return "", extra
