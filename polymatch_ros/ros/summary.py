"""What `polymatch run` reports at the end: the last progress line, the summary table, the
agents' run records, the comparison with the centralised simulation, the verdict."""

import sys
from dataclasses import replace

import numpy as np

from ..console import SUMMARY_HEADER, format_table, summary_rows
from ..core.metrics import ensemble_metrics
from ..core.model import GroupState, State
from ..core.simulate import convergence_verdict, prepare, simulate


def report(args, scene, the_plan, watcher, children, monitor, progress, code, message, wall):
    final = watcher.final_state() if watcher is not None else None
    records = [r for c in children + ([monitor] if monitor else []) for r in c.records()]
    if monitor is not None and not monitor.records() and watcher and watcher.monitor:
        # no final line from the monitor (ended before it wrote one): its last report as the
        # status topic carried it stands in (in lockstep the final step's, see 'received')
        records.append(watcher.monitor)
        print("note: the monitor printed no final record; its last report on the status "
              "topic stands in", file=sys.stderr)
    if args.records:
        with open(args.records, "w", encoding="utf-8") as fh:
            fh.writelines(r.to_json() + "\n" for r in records)
    lead = getattr(args, "lead", True)
    if code == 0 and lead and final is not None:
        _final_progress(progress, scene, final, records)
        _summary(args, scene, the_plan, final, records, wall, watcher)
    elif code == 0 and not lead:
        progress.done()
        _host_line(args, records, wall)
    elif message:
        progress.done()
        print(f"polymatch: error: {message}", file=sys.stderr)
    for c in children + ([monitor] if monitor is not None else []):
        if c.hung_in_teardown():
            who = "the runner" if c.ended_by_runner else "its watchdog"
            print(
                f"note: {c.name} reported its result, then its DDS teardown hung (a rare Fast DDS "
                f"shutdown spin); {who} ended it",
                file=sys.stderr,
            )


def _host_line(args, records, wall):
    """A host without the monitor that ran some agents: what they did; the lead host has the
    summary."""
    from .children import describe_agents

    agents = [r for r in records if r.role == "agent"]
    t = max((r.t for r in agents), default=0.0)
    rate = np.mean([r.rounds_per_second for r in agents]) if agents else 0.0
    print(
        f"agents {describe_agents(args.agents)} ended at t = {t:g}, wall time {wall:.2f} s, "
        f"{rate:.1f} rounds/s per agent (mean); the host that runs the monitor has the summary"
    )


def _final_progress(progress, scene, final, records):
    """The last progress line: the final state's true diameter and the agents' mean rate."""
    met = ensemble_metrics(scene.model, final)
    rates = [r.rounds_per_second for r in records if r.role == "agent"]
    progress.last, progress._ended = -float("inf"), False  # always shown, however recent the last
    progress(final.t, met.diameter, f"  {np.mean(rates) if rates else 0.0:7.1f} rounds/s")
    progress.done()


def _summary(args, scene, the_plan, final, records, wall, watcher):
    met = ensemble_metrics(scene.model, final)
    print(
        f"scene {scene.name}: {scene.model.n_agents} agents, {args.mode}, "
        f"integrator {the_plan.name}, "
        f"dt {the_plan.dt:g}"
    )
    print(format_table(summary_rows(scene, met), SUMMARY_HEADER))
    agents = [r for r in records if r.role == "agent"]
    text = f"t = {final.t:g}, wall time {wall:.2f} s"
    if agents and args.mode == "lockstep":
        text += f", {np.mean([r.rounds_per_second for r in agents]):.1f} rounds/s per agent (mean)"
    print(text)
    for rec in agents:
        if args.verbose or rec.dropped_total:
            print(rec.describe())
    if args.mode == "lockstep":
        for rec in records:
            if rec.role == "monitor":
                print(rec.describe())
    if args.save:
        _save(args.save, scene, final, watcher.pose_times())
    if args.mode == "lockstep" and args.compare:
        central = prepare(scene, the_plan, distributed=True)
        ref = simulate(
            replace(central, t_end=final.t),
            the_plan.name,
            the_plan.dt,
            samples=[final.t],
            keep_states=False,
            metrics=False,
        )
        dev = vertex_deviation(
            central.model, ref.final, _as_rep(central.model, scene.model, final)
        )
        print(
            f"lockstep vs centralised simulation (same integrator and dt) at t = {final.t:g}: "
            f"max vertex deviation {dev:.3e}"
        )


def verdict(scene, watcher):
    final = watcher.final_state()
    met = ensemble_metrics(scene.model, final)
    converged_at = final.t if met.diameter < scene.tolerance else None
    code, msg = convergence_verdict(scene, met.diameter, converged_at)
    print(msg)
    return code


def _save(path, scene, final, times):
    data = {"t": final.t, "origin": scene.origin}
    for gi, g in enumerate(scene.model.groups):
        data[f"group{gi}_times"] = np.array([times[a] for a in g.indices])
    for gi, gs in enumerate(final.groups):
        data[f"group{gi}_centroids"] = gs.x + scene.origin
        data[f"group{gi}_rotations"] = scene.model.rotations.to_matrices(gs.rot)
    np.savez(path, **data)
    print(f"final poses (as received on the pose topics) saved to {path}")


def vertex_deviation(model, a, b):
    """max over agents and vertices of |x^i_a(a) - x^i_a(b)|."""
    worst = 0.0
    grp = model.rotations
    for g, ga, gb in zip(model.groups, a.groups, b.groups):
        for r in g.reference:
            pa = ga.x + grp.rotate(ga.rot, r)
            pb = gb.x + grp.rotate(gb.rot, r)
            worst = max(worst, float(np.max(np.linalg.norm(pa - pb, axis=1))))
    return worst


def _as_rep(target_model, model, state):
    if type(target_model.rotations) is type(model.rotations):
        return state
    src, dst = model.rotations, target_model.rotations
    return State(
        state.t,
        tuple(
            GroupState(gs.x, dst.from_matrices(src.to_matrices(gs.rot)), gs.v, None)
            for gs in state.groups
        ),
    )
