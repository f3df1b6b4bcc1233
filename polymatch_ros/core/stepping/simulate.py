"""The centralised simulator: scene -> trajectory at sample times, with per-group metrics.

``simulate`` runs the same steppers the ROS agents run (``drive`` answers
each stage with the simulator's own arrays), picks the integrator the scene
asks for (or the recommended one for its kind), refuses unstable fixed steps,
and records metrics only at sample times so they never dominate the run.
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np

from .. import proximity
from ..errors import PolymatchError, StabilityError
from ..metrics import EnsembleMetrics, ensemble_metrics, stationarity
from ..model import Group, GroupState, Model, State, System
from ..proximity import Components, ComponentTracker
from ..so import group_for
from .integrators import check_stability, get_method, max_stable_dt
from .solver import RUNNING, Method, drive, step_grid

if TYPE_CHECKING:
    from ..scenes.scene import Scene
    from .adaptive import AdaptiveLie

__all__ = ["EXIT_NOT_CONVERGED", "NumericalPlan", "Trajectory", "choose_numerics",
           "convergence_verdict", "drive", "explain", "group_components", "prepare", "recommend",
           "simulate", "step_grid", "with_representation"]

EXIT_NOT_CONVERGED = 3


@dataclass
class NumericalPlan:
    """The integrator a run will use, and why."""

    method: Method | AdaptiveLie
    dt: float | None = None            # None: adaptive (see tolerance)
    tolerance: float | None = None
    reason: str = ""

    @property
    def name(self) -> str:
        return self.method.name


def with_representation(scene: Scene, representation: str) -> Scene:
    """The same scene with rotations in another representation ('matrix': the full model)."""
    model = scene.model
    new = group_for(model.dim, representation)
    same_map = getattr(new, "retraction", None) == model.rotations.retraction
    if type(new) is type(model.rotations) and same_map:
        return scene
    old = model.rotations
    groups = []
    for gs in scene.initial.all_groups():
        rot = new.from_matrices(old.to_matrices(gs.rot))
        w = None if gs.w is None else new.algebra_from_skew(old.algebra_to_skew(gs.w))
        groups.append(GroupState(gs.x.copy(), rot, None if gs.v is None else gs.v.copy(), w))
    return replace(scene, model=replace(model, rotations=new), initial=State(0.0, tuple(groups)))


def recommend(scene: Scene, distributed: bool = False) -> tuple[str, str]:
    """(method name, reason) recommended for the scene (docs/guide/speed-and-accuracy.md)."""
    m = scene.model
    if m.order == 1:
        if scene.integrator.tolerance is not None and not distributed:
            return "adaptive", "a tolerance was asked for (centralised)"
        return "rkmk4", "first order: 4th-order Munthe-Kaas, 4 rounds per step"
    if m.gamma == 0:
        return "lie_verlet", ("undamped (gamma = 0): symplectic splitting keeps the energy "
                              "without drift")
    dt = scene.integrator.step
    if m.mass / m.gamma < 0.5 * dt:
        return "etd2", (f"m/gamma = {m.mass / m.gamma:.3g} < dt/2: damping is stiff, "
                        "integrate it exactly "
                        "(an explicit adaptive method would crawl at the stability limit)")
    if scene.integrator.tolerance is not None and not distributed:
        return "adaptive", "a tolerance was asked for (centralised)"
    return "rkmk4", "second order, non-stiff: 4th-order Munthe-Kaas"


def choose_method(scene: Scene, method: str | None = None, tolerance: float | None = None,
                  distributed: bool = False) -> tuple[str, str]:
    """(name, how it was chosen): explicit choice > scene file > ``recommend`` (which sees the
    tolerance asked for, if any)."""
    name = method or scene.integrator.method
    if name != "auto":
        return name, "chosen explicitly" if method else "from the scene file"
    if tolerance is not None:
        scene = replace(scene, integrator=replace(scene.integrator, tolerance=tolerance))
    name, reason = recommend(scene, distributed)
    return name, f"auto picked it: {reason}"


def choose_numerics(scene: Scene, method: str | None = None, dt: float | None = None,
                    tolerance: float | None = None, distributed: bool = False,
                    check: bool = True) -> NumericalPlan:
    """The run's numerical plan: the integrator (``choose_method``) and its step; stability
    checked."""
    name, reason = choose_method(scene, method, tolerance, distributed)
    tol = tolerance if tolerance is not None else scene.integrator.tolerance
    if name == "adaptive":
        from .adaptive import AdaptiveLie
        if distributed:
            raise PolymatchError("the adaptive integrator runs centralised only; "
                                 "pick a fixed-step method")
        from ..scenes.scene import DEFAULT_TOLERANCE
        tol = tol or DEFAULT_TOLERANCE
        return NumericalPlan(AdaptiveLie(tol, max_steps=scene.integrator.max_steps), None, tol,
                             reason)
    meth = get_method(name)
    step = dt if dt is not None else scene.integrator.step
    if not step > 0 or not math.isfinite(step):
        raise PolymatchError(f"dt must be a positive number, got {step}")
    if step > scene.t_end:
        warnings.warn(f"dt = {step:g} is larger than t_end = {scene.t_end:g}: "
                      "taking one step of t_end", stacklevel=2)
        step = scene.t_end
    if check:
        check_stability(meth, scene.model, step)
    return NumericalPlan(meth, step, None, reason)


def prepare(scene: Scene, numerics: NumericalPlan, distributed: bool = False) -> Scene:
    """Scene in the representation the method needs (projection baselines work on matrices).

    ``distributed`` on a communication graph: the centroids are integrated with the stages
    (``model.centroids: integrated``).  The exact flow of Prop 2.1 on a graph is a global
    linear map that reads every agent's centroid at each step; integrated, every exchange
    stays between in-neighbours (the same model; the two differ by the integrator's error).
    """
    m = scene.model
    if distributed and m.centroids_exact and any(g.graph is not None for g in m.groups):
        scene = replace(scene, model=replace(m, centroids="integrated"))
    if numerics.method.info.family == "projection" and scene.model.rotations.name == "angle":
        return with_representation(scene, "matrix")
    return scene


@dataclass
class Trajectory:
    scene: Scene
    numerics: NumericalPlan
    times: list[float] = field(default_factory=list)
    metrics: list[EnsembleMetrics] = field(default_factory=list)
    states: list[State] = field(default_factory=list)
    steps: int = 0
    rhs_evals: int = 0
    wall_time: float = 0.0
    final: State | None = None
    converged_at: float | None = None
    stationarity: float | None = None
    #: per proximity-graph group, its components at the last sample and since when they held
    components: tuple[Components, ...] = ()
    #: every change of a proximity graph's components over the samples (the first included)
    component_history: list[Components] = field(default_factory=list)

    @property
    def diameters(self) -> np.ndarray:
        return np.array([m.diameter for m in self.metrics])

    @property
    def converged(self) -> bool:
        return self.converged_at is not None


class _Recorder:
    """Metrics (and states) at sample times; says when a run may stop (converged)."""

    def __init__(self, traj, metrics, keep_states, progress, stop_when_converged):
        self.traj, self.metrics, self.keep_states = traj, metrics, keep_states
        self.progress, self.stop_when_converged = progress, stop_when_converged
        self.below = None           # time from which the diameter has stayed under tolerance
        self.last = None
        self.tracker = ComponentTracker()
        self.proximity = any(g.graph is not None and g.graph.dynamic
                             for g in traj.scene.model.groups)

    def record(self, st: State) -> bool:
        traj, scene = self.traj, self.traj.scene
        traj.times.append(st.t)
        self.last = st
        if self.metrics:
            met = ensemble_metrics(scene.model, st)
            traj.metrics.append(met)
            if met.diameter < scene.tolerance:
                if self.below is None:
                    self.below = st.t
            else:
                self.below = None
            if self.progress is not None:
                self.progress(st.t, met.diameter)
        if self.keep_states:
            traj.states.append(st)
        if self.proximity:          # who hears whom at this sample (a KD-tree, O(N log N))
            traj.components = group_components(scene.model, st, self.tracker)
            traj.component_history = self.tracker.history
        return self.stop_when_converged and self.below is not None


def simulate(scene: Scene, method: str | None = None, dt: float | None = None,
             tolerance: float | None = None, *, samples: Sequence[float] | None = None,
             keep_states: bool = True, progress: Callable[[float, float], None] | None = None,
             stop_when_converged: bool = False, check_stability: bool = True,
             metrics: bool = True) -> Trajectory:
    """Run the scene centralised; return a ``Trajectory`` with metrics at the sample times.

    Fixed-step runs take steps of dt (the last one clipped to t_end); sample times
    are rounded to the nearest step; the adaptive method interpolates them.
    ``progress(t, diameter)`` is called at samples.  One loop drives every method's run
    (``solver.FixedStepSolver`` or ``adaptive.AdaptiveSolver``).
    """
    numerics = choose_numerics(scene, method, dt, tolerance, check=check_stability)
    scene = prepare(scene, numerics)
    system = System(scene.model)
    times = np.asarray(scene.samples if samples is None else samples, dtype=float)
    traj = Trajectory(scene, numerics)
    state = State(0.0, tuple(replace(gs) for gs in scene.initial.all_groups()))
    t0 = time.perf_counter()
    recorder = _Recorder(traj, metrics, keep_states, progress, stop_when_converged)
    stop = recorder.record(state)
    if not stop:
        run = numerics.method.solver(system, state, scene.t_end, times, numerics.dt)
        while not stop and run.status == RUNNING:
            for st in run.step():
                stop = recorder.record(st)
                if stop:
                    break
        traj.steps, traj.rhs_evals = run.nsteps, run.nfev
        state = recorder.last if stop else run.state
    traj.wall_time = time.perf_counter() - t0
    traj.final = state
    traj.converged_at = recorder.below
    traj.stationarity = stationarity(system, state)
    return traj


def explain(scene: Scene, method: str | None = None, dt: float | None = None,
            tolerance: float | None = None, distributed: bool = False) -> list[str]:
    """Lines saying which model, representation and integrator the scene will use, and why."""
    m = scene.model
    lines = [f"scene {scene.name!r}: d = {m.dim}, {m.n_agents} agents in {len(m.groups)} group(s)"]
    if m.order == 1:
        lines.append(f"model: first order (A-2), kappa = {m.kappa:g}, gamma = {m.gamma:g}: "
                     "no velocities are carried")
    else:
        lines.append(f"model: second order (A-1), m = {m.mass:g}, gamma = {m.gamma:g}, "
                     f"kappa = {m.kappa:g}")
    for g in m.groups:
        kind = "similar (F-1: torque weights s_k/s_i)" if g.scales is not None else \
            "congruent (no scale weights)"
        lines.append(f"group {g.name!r}: {g.size} x {len(g.reference)}-vertex polytope, {kind}")
        lines.append(f"group {g.name!r} graph: {_graph_line(g)}")
    lines.append(_centroid_line(m, distributed))
    rep = m.rotations
    rep_text = {"angle": "angles (SO(2) is abelian: the first-order model is Kuramoto, "
                         "exp is addition)",
                "so3": f"3x3 matrices, structure-of-arrays, {rep.retraction} map in closed form",
                "matrix": f"{m.dim}x{m.dim} matrices, Cayley map, no per-matrix solves"}[rep.name]
    lines.append(f"rotations: {rep_text}")
    p = choose_numerics(scene, method, dt, tolerance, distributed=distributed, check=False)
    info = p.method.info
    if isinstance(p.method, Method) and p.dt is not None:
        try:
            check_stability(p.method, m, p.dt)
            limit = max_stable_dt(p.method, m, 1e6)
            stab = (f"linear stability limit dt < {limit:.3g}" if limit < 1e6
                    else "no stability limit found")
        except StabilityError as exc:
            stab = f"REFUSED: {exc}"
        lines.append(f"integrator: {info.name} (order {info.order}, {info.stages} "
                     f"evaluation(s)/step, {info.rounds} exchange round(s)/step in lockstep), "
                     f"dt = {p.dt:g} — {p.reason}; {stab}")
        if info.family == "projection" and rep.name == "angle":
            lines.append("projection baselines need matrices: "
                         "the run uses the full 2x2 matrix model")
    else:
        lines.append(f"integrator: adaptive DOP853-Lie, tolerance {p.tolerance:g} — {p.reason}")
    lines.extend(f"note: {n}" for n in scene.notes)
    return lines


def _centroid_line(m: Model, distributed: bool) -> str:
    """How the centroids advance: exact flow (Prop. 2.1) or with the method's stages."""
    if m.inter_group:
        return (f"mixed ensemble (F-2): kappa_2 = {m.kappa_2:g}, L = {m.L:g}; "
                "centroids integrated "
                "with the method's stages (the inter-group force is nonlinear)")
    if distributed and m.centroids_exact and any(g.graph is not None for g in m.groups):
        return ("centroids: integrated with the method's stages in a distributed run on a "
                "graph (the exact Laplacian flow reads every agent; stages keep the "
                "exchange between in-neighbours)")
    if m.centroids_exact and any(g.graph is not None for g in m.groups):
        return ("centroids: exact linear flow of Proposition 2.1 (no inter-group potential);"
                " on graphs mode by mode of the Laplacian (eigh once, O(N^3); O(N^2 d) "
                "per step)")
    if m.centroids_exact:
        return "centroids: exact linear flow of Proposition 2.1 (no inter-group potential)"
    if any(g.graph is not None and g.graph.dynamic for g in m.groups):
        return ("centroids: integrated with the method's stages (a proximity graph: weights "
                "that depend on the centroids make their consensus nonlinear)")
    if m.centroids == "exact":
        return ("centroids: integrated with the method's stages (a directed graph: "
                "its Laplacian is not symmetric; stages keep the exchange between "
                "in-neighbours)")
    return ("centroids: integrated with the method's stages (model.centroids = integrated; "
            "the exact flow would be cheaper and exact)")


def _graph_line(g: Group) -> str:
    """Which graph a group couples on and what an evaluation costs there."""
    if g.graph is None:
        return "complete (the paper's mean field S = sum_k O_k: O(N d^3) per evaluation)"
    text = g.graph.describe()
    if g.graph.dynamic:
        return text
    if g.graph.allow_disconnected and g.graph.components.max(initial=0) > 0:
        text += (f"; {int(g.graph.components.max()) + 1} components (allow_disconnected): "
                 "the metrics report each one's diameter")
    return text


def group_components(model: Model, state: State,
                     tracker: ComponentTracker | None = None) -> tuple[Components, ...]:
    """The components of every proximity-graph group of a whole ensemble's ``state`` (since
    when: from ``tracker``, which has seen the earlier states; without one, ``since`` is None)."""
    out = []
    for g, gs in zip(model.groups, state.all_groups()):
        if g.graph is None or not g.graph.dynamic:
            continue
        agents = np.arange(g.start, g.start + g.size)
        if tracker is not None:
            out.append(tracker.update(state.t, g.name, g.graph.radius, agents, gs.x))
        else:
            parts = proximity.parts_of(agents, proximity.components(gs.x, g.graph.radius))
            out.append(Components(g.name, g.graph.radius, parts, None, float(state.t)))
    return tuple(out)


def convergence_verdict(scene: Scene, diameter: float, converged_at: float | None,
                        stationarity: float | None = None,
                        metrics: EnsembleMetrics | None = None,
                        components: Sequence[Components] = ()) -> tuple[int, str]:
    """(exit code, message) for the end of a run.

    ``metrics`` (the last sample's) adds the per-component diameters of disconnected graphs;
    ``components`` names the agents of each split proximity graph and since when it is split.
    """
    if converged_at is not None:
        return 0, f"converged: matching diameter < {scene.tolerance:g} from t = {converged_at:g}"
    msg = (f"did not converge: matching diameter {diameter:.3e} >= tolerance "
           f"{scene.tolerance:g} at t_end")
    splits = {c.group: c for c in components if c.split}
    parts_diameters = None if metrics is None else metrics.component_diameters
    for g, diameters in zip(scene.model.groups, parts_diameters or ()):
        if diameters is not None:
            parts = ", ".join(f"{d:.3e}" for d in diameters)
            if g.name in splits:
                msg += f"; {splits[g.name].describe()}, component diameters [{parts}]"
                del splits[g.name]
            else:
                msg += f"; group {g.name!r} is disconnected, component diameters [{parts}]"
    msg += "".join(f"; {c.describe()}" for c in splits.values())
    if any(c.split for c in components):
        msg += ("; consensus on a proximity graph needs the union of its graphs over time to "
                "stay connected (Jadbabaie, Lin & Morse 2003; Moreau 2005)")
    elif stationarity is not None and stationarity < 1e-9 * max(1.0, scene.model.kappa):
        graphs = any(g.graph is not None for g in scene.model.groups)
        msg += ("; the rotations sit at an equilibrium that is not consensus "
                f"(|W| = {stationarity:.1e}),"
                + (" e.g. a twisted state theta_i = 2 pi q i / N of a ring (stable on graphs"
                   " where the complete graph has none), antipodal or splay states" if graphs
                   else " e.g. antipodal or splay states of the Lohe model"))
    if not scene.expect_convergence:
        return 0, msg + " (the scene expects this: convergence.expected = false)"
    return EXIT_NOT_CONVERGED, msg
