"""The scene commands: ``simulate``, ``explain``, ``integrators``, ``scenes`` (no ROS).

    polymatch simulate SCENE     centralised run: progress, summary table, npz, PNG snapshots
    polymatch explain SCENE      which model, representation and integrator, and why
    polymatch integrators        the registry: order, evaluations and exchange rounds per step
    polymatch scenes             the scenes shipped in config/
"""

from __future__ import annotations

import argparse
import os
import warnings
from typing import Any

import numpy as np

from ..console import (
    SUMMARY_HEADER,
    Progress,
    check_integrator_option,
    format_table,
    load_scene_options,
    memory_size,
    naming_dt_option,
    positive_float,
    summary_rows,
    tolerance_arg,
    writable_output,
)
from ..core.certificate import certify
from ..core.errors import PolymatchError
from ..core.scenes.limits import Limits
from ..core.scenes.preflight import check_run
from ..core.scenes.scene import Scene, load_scene, shipped_config_dirs
from ..core.stepping.simulate import Trajectory, convergence_verdict


def _limits(args: argparse.Namespace) -> Limits | None:
    return Limits(memory=args.memory_limit) if getattr(args, "memory_limit", None) else None


def cmd_simulate(args: argparse.Namespace) -> int:
    """A centralised run of a scene: progress, summary table, verdict; npz and figure."""
    from ..core.stepping.simulate import choose_numerics, explain, simulate
    save = writable_output(args.save, ".npz") if args.save else None
    figure = writable_output(args.figure, ".png") if args.figure else None
    check_integrator_option(args.integrator)
    scene = load_scene_options(args.scene, args.t_end, limits=_limits(args))
    samples: Any = None  # sample times (an array), or the scene's
    if figure:
        samples = np.unique(np.concatenate([scene.samples,
                                            [t for t in scene.snapshots if t <= scene.t_end]]))
    kept = len(scene.samples if samples is None else samples) if (save or figure) else 0
    check_run(scene, args.integrator, args.dt, args.tolerance, kept_samples=kept,
              limits=_limits(args))
    if args.explain:
        print("\n".join(explain(scene, args.integrator, args.dt, args.tolerance)))
        print(certificate_line(scene))
        with naming_dt_option(args.dt):      # a refusal: its error, exit 2
            choose_numerics(scene, args.integrator, args.dt, args.tolerance)
        return 0
    progress = Progress(scene.t_end, args.quiet)
    with naming_dt_option(args.dt):
        traj = simulate(scene, args.integrator, args.dt, args.tolerance, samples=samples,
                        keep_states=bool(save or figure), progress=progress,
                        stop_when_converged=args.stop_when_converged)
    progress.done()
    p = traj.numerics
    print(f"scene {scene.name}: {scene.model.n_agents} agents, d = {scene.dim}, "
          f"integrator {p.name}"
          + (f" dt = {p.dt:g}" if p.dt else f" tolerance = {p.tolerance:g}"))
    print(format_table(summary_rows(traj.scene, traj.metrics[-1]), SUMMARY_HEADER))
    print(f"t = {traj.times[-1]:g}, steps {traj.steps}, right-hand sides {traj.rhs_evals}, "
          f"wall time {traj.wall_time:.3f} s")
    if traj.metrics[-1].group_separation is not None:
        print(f"distance between group centres: {traj.metrics[-1].group_separation:.4g} "
              f"(L = {scene.model.L:g})")
    if save:
        save_npz(traj, save)
        print(f"trajectory saved to {save}")
    if figure:
        from ..figures import snapshot_figure
        snapshot_figure(traj, figure)
        print(f"snapshots saved to {figure}")
    code, msg = convergence_verdict(scene, traj.metrics[-1].diameter, traj.converged_at,
                                    traj.stationarity, metrics=traj.metrics[-1],
                                    components=traj.components)
    print(certificate_line(scene))      # of the initial state, beside the observed verdict
    print(msg)
    return code


def save_npz(traj: Trajectory, path: str) -> None:
    """The trajectory, its metrics and the scene's polytopes, in the one ``--save`` layout
    (``core.saved``)."""
    from ..core.saved import save_states
    save_states(path, traj.scene, traj.states, traj.metrics)


def cmd_explain(args: argparse.Namespace) -> int:
    """Which model, representation and integrator a scene uses, and why; then, for a run
    that ``simulate`` would refuse, the refusal as an error (exit code 2)."""
    from ..core.stepping.simulate import choose_numerics, explain
    check_integrator_option(args.integrator)
    scene = load_scene(args.scene, limits=_limits(args))
    check_run(scene, args.integrator, args.dt, args.tolerance, distributed=args.distributed,
              limits=_limits(args))
    print("\n".join(explain(scene, args.integrator, args.dt, args.tolerance,
                            distributed=args.distributed)))
    print(certificate_line(scene))
    with naming_dt_option(args.dt):
        choose_numerics(scene, args.integrator, args.dt, args.tolerance,
                        distributed=args.distributed)
    return 0


def certificate_line(scene: Scene) -> str:
    """The certificate of the scene's initial state (``core.certificate``), at t = 0."""
    return certify(scene.model, scene.initial, scene.tolerance).line()


def cmd_integrators(args: argparse.Namespace) -> int:
    """The integrator registry as a table."""
    from ..core.stepping.adaptive import AdaptiveLie
    from ..core.stepping.integrators import METHODS
    rows = []
    for m in list(METHODS.values()) + [AdaptiveLie]:
        i = m.info
        models = "/".join({1: "1st", 2: "2nd"}[k] for k in i.models)
        rows.append([i.name, i.order, i.stages, i.rounds if i.rounds else "-", i.family, models,
                     i.summary])
    print(format_table(rows, ["name", "order", "evals/step", "rounds/step", "family", "models",
                              "what"]))
    return 0


def cmd_scenes(args: argparse.Namespace) -> int:
    """The shipped scenes as a table; ``simulate`` says whether the scene runs as shipped or is
    kept to show a refusal (``polymatch simulate`` exits 2 with the reason)."""
    from ..core.stepping.simulate import choose_numerics
    rows: list[list[object]] = []
    for d in shipped_config_dirs()[:1]:
        for sub in ("", "extremes"):
            folder = os.path.join(d, sub)
            if not os.path.isdir(folder):
                continue
            for f in sorted(os.listdir(folder)):
                if not f.endswith(".yaml"):
                    continue
                name = os.path.join(sub, f[:-5]) if sub else f[:-5]
                try:
                    with warnings.catch_warnings():
                        warnings.simplefilter("ignore")
                        s = load_scene(os.path.join(folder, f))
                except PolymatchError as exc:
                    rows.append([name, "?", "?", "?", "invalid", f"invalid: {exc}"])
                    continue
                try:
                    choose_numerics(s)
                    runs = "runs"
                except PolymatchError:
                    runs = "refused"             # kept to show how a refusal reads
                rows.append([name, s.dim, s.model.n_agents, s.model.order, runs, s.description])
    print(format_table(rows, ["scene", "d", "N", "order", "simulate", "description"]))
    print("refused: kept to show a refusal; `polymatch simulate SCENE` names the cause "
          "and exits 2")
    return 0


def add_integrator_options(p: argparse.ArgumentParser) -> None:
    """--integrator, --dt, --tolerance and --memory-limit."""
    p.add_argument("--integrator", "-i", metavar="NAME",
                   help="integrator (see `polymatch integrators`)")
    p.add_argument("--dt", type=positive_float, help="fixed step size (fixed-step methods only)")
    p.add_argument("--tolerance", type=tolerance_arg,
                   help="relative tolerance in [1e-14, 1) (the adaptive integrator only)")
    p.add_argument("--memory-limit", type=memory_size, metavar="SIZE",
                   help="refuse scenes estimated to need more memory (default 2G), e.g. 8G")


def add_parser(sub: argparse._SubParsersAction) -> None:
    """The four scene commands' parsers."""
    p = sub.add_parser("simulate", help="centralised simulation of a scene")
    p.add_argument("scene", help="scene file or shipped scene name")
    add_integrator_options(p)
    p.add_argument("--t-end", type=positive_float, help="override time.t_end")
    p.add_argument("--save", metavar="NPZ", help="save the trajectory (npz)")
    p.add_argument("--figure", metavar="PNG", help="render the snapshot figure (needs matplotlib)")
    p.add_argument("--explain", action="store_true",
                   help="say which model and integrator, then exit")
    p.add_argument("--stop-when-converged", action="store_true",
                   help="stop at the first sample under tolerance")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress line")
    p.set_defaults(func=cmd_simulate)

    p = sub.add_parser("explain",
                       help="which model, representation and integrator a scene uses, and why")
    p.add_argument("scene", help="scene file or shipped scene name")
    add_integrator_options(p)
    p.add_argument("--distributed", action="store_true", help="as the ROS node set would run it")
    p.set_defaults(func=cmd_explain)

    p = sub.add_parser("integrators", help="list the integrators")
    p.set_defaults(func=cmd_integrators)
    p = sub.add_parser("scenes", help="list the shipped scenes")
    p.set_defaults(func=cmd_scenes)
