"""Pure numerical core of polymatch_ros (numpy/scipy only, no ROS).

    scene = load_scene("config/congruent_triangles.yaml")
    traj = simulate(scene)                 # centralised, metrics at sample times
    traj.diameters[-1], traj.final         # matching diameter, final state

The ROS agents, the monitor and the benchmarks use exactly these pieces:
``System`` (model + mean field), the integrator registry ``METHODS``,
``advance`` (one step) and ``ensemble_metrics``.
"""

import importlib

_WHERE = {
    "AdaptiveLie": "adaptive", "decompose": "decompose",
    "ParameterError": "errors", "PolymatchError": "errors", "SceneError": "errors", "ShapeError": "errors",
    "StabilityError": "errors",
    "METHODS": "integrators", "check_stability": "integrators", "get_method": "integrators",
    "max_stable_dt": "integrators",
    "ensemble_metrics": "metrics", "point_set_diameter": "metrics",
    "Coupling": "model", "GroupState": "model", "Model": "model", "State": "model", "System": "model",
    "Scene": "scene", "load_scene": "scene",
    "Trajectory": "simulate", "advance": "simulate", "explain": "simulate", "plan": "simulate",
    "recommend": "simulate", "simulate": "simulate", "with_representation": "simulate",
}


def __getattr__(name):
    """Import on first use: a ROS agent needs the model and steppers, not scipy.integrate."""
    if name in _WHERE:
        return getattr(importlib.import_module(f".{_WHERE[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "AdaptiveLie", "Coupling", "GroupState", "METHODS", "Model", "ParameterError", "PolymatchError",
    "Scene", "SceneError", "ShapeError", "StabilityError", "State", "System", "Trajectory", "advance",
    "check_stability", "decompose", "ensemble_metrics", "explain", "get_method", "load_scene",
    "max_stable_dt", "plan", "point_set_diameter", "recommend", "simulate", "with_representation",
]
