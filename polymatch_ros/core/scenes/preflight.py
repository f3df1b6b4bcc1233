"""Before a run: refuse options that would be ignored and runs that would not fit.

``check_run`` resolves the integrator as ``simulate.choose_numerics`` does
(``simulate.choose_method``: explicit choice > scene file > recommendation) and then refuses,
with one line naming the option:

- ``--dt`` for the adaptive integrator, ``--tolerance`` for a fixed-step one (a scene's own
  ``integrator.dt``/``tolerance`` that ``method: auto`` does not use gives a warning);
- a fixed-step run of more than ``integrator.max_steps`` steps;
- a run whose estimated memory (agents x vertices, kept samples, the step grid) exceeds
  the limit (``--memory-limit``).
"""

import warnings

from ..errors import ParameterError, SceneError
from ..stepping.simulate import choose_method
from .limits import FLOAT, Budget, Limits
from .scene import Scene, check_step_count


def check_run(scene: Scene, method: str | None = None, dt: float | None = None,
              tolerance: float | None = None, *, distributed: bool = False,
              kept_samples: int = 0, limits: Limits | None = None) -> int:
    """Refuse (ParameterError/SceneError) or warn before any step is taken; return the steps."""
    name, why = choose_method(scene, method, tolerance, distributed)
    spec = scene.integrator
    if name == "adaptive":
        _refuse_unused("dt", dt, spec.dt, f"the adaptive integrator chooses its own steps ({why})",
                       "use --tolerance, or pick a fixed-step method with -i")
        steps = 0
    else:
        _refuse_unused("tolerance", tolerance, spec.tolerance, f"{name} takes fixed steps ({why})",
                       "use --dt, or -i adaptive for a tolerance")
        step = dt if dt is not None else spec.step
        where = "--dt" if dt is not None else "integrator.dt"
        try:
            steps = check_step_count(scene.t_end, step, spec.max_steps, where)
        except SceneError as exc:
            if dt is None:
                raise
            raise ParameterError(str(exc)) from None
    _check_memory(scene, steps, kept_samples, limits)
    return steps


def _refuse_unused(option, given, in_scene, reason, instead):
    """Refuse ``--option`` given on the command line, warn about the scene's
    ``integrator.option``: the resolved integrator would not use either (``reason``)."""
    if given is not None:
        raise ParameterError(f"--{option}: {reason}; {instead}")
    if in_scene is not None:
        warnings.warn(f"integrator.{option} = {in_scene:g} is not used: {reason}", stacklevel=3)


def _check_memory(scene, steps, kept_samples, limits):
    budget = Budget(limits)
    model = scene.model
    for gi, g in enumerate(model.groups):
        budget.charge_agents(f"groups[{gi}]", g.size, len(g.reference), model.dim, model.order)
    budget.charge("time.samples", len(scene.samples) * 2048,
                  f"metrics at {len(scene.samples)} samples")
    if kept_samples:
        per_state = model.n_agents * (model.dim + model.dim ** 2) * model.order * FLOAT
        budget.charge("time.samples", 3.0 * kept_samples * per_state,
                      f"{kept_samples} states kept for --save/--figure")
    if steps:
        budget.charge("integrator.dt", 3.0 * steps * FLOAT, f"a grid of {steps} steps")
