"""`polymatch` — one command, subcommands for every job.

    polymatch simulate SCENE     centralised run: progress, summary table, npz, PNG snapshots
    polymatch explain SCENE      which model, representation and integrator, and why
    polymatch integrators        the registry: order, evaluations and exchange rounds per step
    polymatch scenes             the scenes shipped in config/
    polymatch run SCENE          the distributed ROS 2 ensemble (one process per agent) + monitor
    polymatch agent | monitor    single ROS 2 nodes (= `ros2 run polymatch_ros agent|monitor`)
    polymatch robot              a simulated robot for bridge mode (= `ros2 run ... robot`)
    polymatch echo TOPIC         print a topic (stand-in for `ros2 topic echo`)
    polymatch sweep [SCENE]      many random ensembles in batches: which initial states match
    polymatch bench WHAT         benchmarks (figures for README)

Errors are one line on stderr and a non-zero exit code: 2 for bad input
(scene, parameters, command line), 3 for a run that did not converge although
the scene expects it, 1 for anything else.  POLYMATCH_DEBUG=1 shows the
traceback of an unexpected error instead of its one line.
"""

import argparse
import os
import sys
import warnings

import numpy as np

from .console import (
    SUMMARY_HEADER,
    Progress,
    format_table,
    memory_size,
    positive_float,
    summary_rows,
    tolerance_arg,
    writable_output,
)
from .core.errors import PolymatchError
from .core.limits import Limits
from .core.preflight import check_run
from .core.scene import load_scene, shipped_config_dirs
from .core.simulate import convergence_verdict


class Parser(argparse.ArgumentParser):
    """argparse with one-line errors (``polymatch: error: ...; see ...--help``), exit code 2.

    Subparsers inherit the class (``add_subparsers`` uses the parent's), so every
    subcommand, including those other modules add, reports parse errors the same way.
    """

    def error(self, message):
        hint = f"see `{self.prog} --help`"
        self.exit(2, f"polymatch: error: {message.splitlines()[0]} ({hint})\n")


def _limits(args):
    return Limits(memory=args.memory_limit) if getattr(args, "memory_limit", None) else None

def cmd_simulate(args):
    from .core.simulate import explain, simulate
    save = writable_output(args.save, ".npz") if args.save else None
    figure = writable_output(args.figure, ".png") if args.figure else None
    scene = load_scene(args.scene, {"time.t_end": args.t_end}, limits=_limits(args))
    samples = None
    if figure:
        samples = np.unique(np.concatenate([scene.samples,
                                            [t for t in scene.snapshots if t <= scene.t_end]]))
    kept = len(scene.samples if samples is None else samples) if (save or figure) else 0
    check_run(scene, args.integrator, args.dt, args.tolerance, kept_samples=kept,
              limits=_limits(args))
    if args.explain:
        print("\n".join(explain(scene, args.integrator, args.dt, args.tolerance)))
        return 0
    progress = Progress(scene.t_end, args.quiet)
    traj = simulate(scene, args.integrator, args.dt, args.tolerance, samples=samples,
                    keep_states=bool(save or figure), progress=progress,
                    stop_when_converged=args.stop_when_converged)
    progress.done()
    p = traj.plan
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
        from .figures import snapshot_figure
        snapshot_figure(traj, figure)
        print(f"snapshots saved to {figure}")
    code, msg = convergence_verdict(scene, traj.metrics[-1].diameter, traj.converged_at,
                                    traj.stationarity, metrics=traj.metrics[-1])
    print(msg)
    return code


def save_npz(traj, path):
    scene = traj.scene
    model = scene.model
    data = {"times": np.array(traj.times), "origin": scene.origin,
            "diameter": traj.diameters}
    for gi, g in enumerate(model.groups):
        key = f"group{gi}_"
        data[key + "name"] = np.array(g.name)
        data[key + "reference"] = g.reference
        data[key + "edges"] = np.array(g.edges)
        if g.scales is not None:
            data[key + "scales"] = g.scales
        data[key + "centroids"] = np.array([st.groups[gi].x + scene.origin for st in traj.states])
        data[key + "rotations"] = np.array([model.rotations.to_matrices(st.groups[gi].rot)
                                            for st in traj.states])
        for name in ("centroid_diameter", "rotation_diameter", "matching_diameter", "energy",
                     "orthogonality"):
            data[key + name] = np.array([getattr(m.groups[gi], name) for m in traj.metrics])
    np.savez_compressed(path, **data)


def cmd_explain(args):
    from .core.simulate import explain
    scene = load_scene(args.scene, limits=_limits(args))
    check_run(scene, args.integrator, args.dt, args.tolerance, distributed=args.distributed,
              limits=_limits(args))
    print("\n".join(explain(scene, args.integrator, args.dt, args.tolerance,
                            distributed=args.distributed)))
    return 0


def cmd_integrators(args):
    from .core.adaptive import AdaptiveLie
    from .core.integrators import METHODS
    rows = []
    for m in list(METHODS.values()) + [AdaptiveLie]:
        i = m.info
        models = "/".join({1: "1st", 2: "2nd"}[k] for k in i.models)
        rows.append([i.name, i.order, i.stages, i.rounds if i.rounds else "-", i.family, models,
                     i.summary])
    print(format_table(rows, ["name", "order", "evals/step", "rounds/step", "family", "models",
                              "what"]))
    return 0


def cmd_scenes(args):
    rows = []
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
                    rows.append([name, s.dim, s.model.n_agents, s.model.order, s.description])
                except PolymatchError as exc:
                    rows.append([name, "?", "?", "?", f"invalid: {exc}"])
    print(format_table(rows, ["scene", "d", "N", "order", "description"]))
    return 0


def add_integrator_options(p):
    p.add_argument("--integrator", "-i", metavar="NAME",
                   help="integrator (see `polymatch integrators`)")
    p.add_argument("--dt", type=positive_float, help="fixed step size (fixed-step methods only)")
    p.add_argument("--tolerance", type=tolerance_arg,
                   help="relative tolerance in [1e-14, 1) (the adaptive integrator only)")
    p.add_argument("--memory-limit", type=memory_size, metavar="SIZE",
                   help="refuse scenes estimated to need more memory (default 2G), e.g. 8G")


def build_parser():
    parser = Parser(prog="polymatch", description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

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
    p.add_argument("scene")
    add_integrator_options(p)
    p.add_argument("--distributed", action="store_true", help="as the ROS node set would run it")
    p.set_defaults(func=cmd_explain)

    p = sub.add_parser("integrators", help="list the integrators")
    p.set_defaults(func=cmd_integrators)
    p = sub.add_parser("scenes", help="list the shipped scenes")
    p.set_defaults(func=cmd_scenes)

    for name in PASSTHROUGH:
        sub.add_parser(name, help=f"one {name} node (ROS 2); takes the same arguments as "
                                  f"`ros2 run polymatch_ros {name}`, "
                                  f"e.g. --ros-args -p scene:=FILE")
    for _name, module in (("run", "ros.runner"), ("echo", "ros.echo"), ("set", "ros.param_set"),
                          ("bench", "bench"), ("sweep", "sweep")):
        try:
            mod = __import__(f"polymatch_ros.{module}", fromlist=["add_parser"])
        except ImportError as exc:
            if exc.name and exc.name.startswith("polymatch_ros"):
                continue   # module not present in this build
            raise
        mod.add_parser(sub)
    return parser


PASSTHROUGH = {"agent": "ros.agent_node", "monitor": "ros.monitor_node",
               "robot": "ros.robot_sim"}


def main(argv=None):
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv and argv[0] in PASSTHROUGH:
        mod = __import__(f"polymatch_ros.{PASSTHROUGH[argv[0]]}", fromlist=["main"])
        return mod.main([f"polymatch {argv[0]}"] + argv[1:])
    parser = build_parser()
    args = parser.parse_args(argv)
    warnings.showwarning = _one_line_warning
    try:
        return args.func(args)
    except PolymatchError as exc:
        print(f"polymatch: error: {_one_line(exc)}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print("polymatch: interrupted", file=sys.stderr)
        return 130
    except MemoryError:
        print("polymatch: error: out of memory; lower the scene's sizes or --memory-limit",
              file=sys.stderr)
        return 1
    except Exception as exc:  # noqa: BLE001 -- the contract: one line, never a traceback
        if os.environ.get("POLYMATCH_DEBUG"):
            raise
        print(f"polymatch: internal error: {type(exc).__name__}: {_one_line(exc)} "
              f"(POLYMATCH_DEBUG=1 shows the traceback)", file=sys.stderr)
        return 1


def _one_line(exc):
    text = " ".join(str(exc).split())
    return text if len(text) <= 400 else text[:397] + "..."


def _one_line_warning(message, *args, **kwargs):
    print(f"polymatch: warning: {_one_line(message)}", file=sys.stderr)


if __name__ == "__main__":
    sys.exit(main())
