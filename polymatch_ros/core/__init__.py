"""Pure numerical core of polymatch_ros (numpy/scipy only, no ROS).

    scene = load_scene("config/congruent_triangles.yaml")
    traj = simulate(scene)                 # centralised, metrics at sample times
    traj.diameters[-1], traj.final         # matching diameter, final state

The ROS agents, the monitor and the benchmarks use exactly these pieces:
``System`` (model + mean field, ``lohe_torque``), the integrator registry
``METHODS`` (every method follows ``solver.Method``), ``drive`` (one step) and
``ensemble_metrics`` (an ``EnsembleMetrics`` record).
"""

from .errors import (
    ParameterError,
    PolymatchError,
    SceneError,
    ShapeError,
    StabilityError,
    StepLimitError,
)
from .metrics import EnsembleMetrics, GroupMetrics, ensemble_metrics, point_set_diameter
from .model import Coupling, GroupState, Model, State, System, lohe_torque
from .scenes.decompose import decompose
from .scenes.scene import Scene, load_scene
from .stepping.integrators import METHODS, check_stability, get_method, max_stable_dt
from .stepping.simulate import (
    NumericalPlan,
    Trajectory,
    choose_numerics,
    drive,
    explain,
    recommend,
    simulate,
    with_representation,
)


def __getattr__(name):
    """AdaptiveLie on first use: it pulls in scipy.integrate, which a ROS agent never needs."""
    if name == "AdaptiveLie":
        from .stepping.adaptive import AdaptiveLie
        return AdaptiveLie
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "AdaptiveLie", "Coupling", "EnsembleMetrics", "GroupMetrics", "GroupState", "METHODS",
    "NumericalPlan", "choose_numerics",
    "Model", "ParameterError", "PolymatchError", "Scene", "SceneError", "ShapeError",
    "StabilityError", "State", "StepLimitError", "System", "Trajectory", "check_stability",
    "decompose", "drive", "ensemble_metrics", "explain", "get_method", "load_scene",
    "lohe_torque", "max_stable_dt", "point_set_diameter", "recommend", "simulate",
    "with_representation",
]
