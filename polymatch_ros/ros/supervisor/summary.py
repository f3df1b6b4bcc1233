"""What `polymatch run` reports at the end: the last progress line, the summary table, the
agents' run records, the comparison with the centralised simulation, the verdict."""

from __future__ import annotations

import sys
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, cast

import numpy as np

from ...console import SUMMARY_HEADER, Progress, format_table, summary_rows
from ...core.metrics import ensemble_metrics
from ...core.model import GroupState, Model, State
from ...core.saved import save_states
from ...core.scenes.scene import Scene
from ...core.stepping.simulate import convergence_verdict, group_components, prepare, simulate
from ..wire import RunRecord
from .plan import RunPlan

if TYPE_CHECKING:
    from ..wire.checkpoint import Checkpoint
    from .children import Child
    from .recovery import Failure
    from .watcher import Watcher


@dataclass(frozen=True)
class RunOutcome:
    """How a run ended, for its report: the processes, the watcher, the code and the time."""

    watcher: Watcher | None    # None: the run failed before its node was up
    children: list[Child]      # the agent processes of this host
    monitor: Child | None
    progress: Progress
    code: int                  # 0, or the exit code of the failure
    message: str               # the failure, one line ("" on success)
    wall: float                # wall-clock seconds of the run
    failures: tuple[Failure, ...] = ()   # processes that died, and their restarts
    # each agent process's agents and last checkpoint: the state of a run that ended early
    checkpoints: Sequence[tuple[Sequence[int], Checkpoint | None]] = ()

    @property
    def processes(self) -> list[Child]:
        """The agent processes, then the monitor (if any)."""
        return self.children + ([self.monitor] if self.monitor is not None else [])


def report(plan: RunPlan, outcome: RunOutcome) -> None:
    """The end of the run on stdout/stderr (the summary on the lead host), --run-records
    written."""
    watcher, monitor, progress = outcome.watcher, outcome.monitor, outcome.progress
    final = watcher.final_state() if watcher is not None else None
    records = [r for c in outcome.processes for r in c.records()]
    if monitor is not None and not monitor.records() and watcher and watcher.monitor:
        # no final line from the monitor (ended before it wrote one): its last report as the
        # status topic carried it stands in (in lockstep the final step's, see 'received')
        records.append(watcher.monitor)
        print("note: the monitor printed no final record; its last report on the status "
              "topic stands in", file=sys.stderr)
    if watcher is not None:  # a process ended early (no final line): its last status
        records += [watcher.agents[c.agents] for c in outcome.children
                    if not c.records() and c.agents in watcher.agents]
    if plan.outputs.run_records:
        with open(plan.outputs.run_records, "w", encoding="utf-8") as fh:
            fh.writelines(r.to_json() + "\n" for r in records)
            fh.writelines(f.to_json() + "\n" for f in outcome.failures)
    lead = plan.hosts.lead
    if outcome.code == 0 and lead and final is not None and watcher is not None:
        _final_progress(progress, plan.scene, final, records)
        _summary(plan, final, records, outcome.wall, watcher)
    elif outcome.code == 0 and not lead:
        progress.done()
        _host_line(plan.hosts.agents, records, outcome.wall)
    elif outcome.message:
        progress.done()
        print(f"polymatch: error: {outcome.message}", file=sys.stderr)
    if plan.outputs.save and lead and not (outcome.code == 0 and final is not None):
        _save_partial(plan, outcome)
    _failures(outcome.failures)
    for c in outcome.processes:
        if c.hung_in_teardown():
            who = "the runner" if c.ended_by_runner else "its watchdog"
            print(
                f"note: {c.name} reported its result, then its DDS teardown hung (a rare Fast DDS "
                f"shutdown spin); {who} ended it",
                file=sys.stderr,
            )


def _failures(failures: tuple[Failure, ...]) -> None:
    """One line per process death and what followed (stdout, after the summary)."""
    if not failures:
        return
    restarted = sum(f.restarted is not None for f in failures)
    print(f"failures: {len(failures)} process death(s), {restarted} restarted")
    for f in failures:
        print(f"  {f.describe()}")


def _host_line(here: tuple[int, ...], records: list[RunRecord], wall: float) -> None:
    """A host without the monitor that ran some agents: what they did; the lead host has the
    summary."""
    from .children import describe_agents

    agents = [r for r in records if r.role == "agent"]
    t = max((r.t for r in agents), default=0.0)
    rate = np.mean([r.rounds_per_second for r in agents]) if agents else 0.0
    print(
        f"agents {describe_agents(here)} ended at t = {t:g}, wall time {wall:.2f} s, "
        f"{rate:.1f} rounds/s per agent (mean); the host that runs the monitor has the summary"
    )


def _final_progress(progress: Progress, scene: Scene, final: State,
                    records: list[RunRecord]) -> None:
    """The last progress line: the final state's true diameter and the agents' mean rate."""
    met = ensemble_metrics(scene.model, final)
    rates = [r.rounds_per_second for r in records if r.role == "agent"]
    progress.last, progress._ended = -float("inf"), False  # always shown, however recent the last
    progress(final.t, met.diameter, f"  {np.mean(rates) if rates else 0.0:7.1f} rounds/s")
    progress.done()


def _summary(plan: RunPlan, final: State, records: list[RunRecord], wall: float,
             watcher: Watcher) -> None:
    scene, the_plan, mode, outputs = plan.scene, plan.numerics, plan.mode, plan.outputs
    met = ensemble_metrics(scene.model, final)
    print(
        f"scene {scene.name}: {scene.model.n_agents} agents, {mode}, "
        f"integrator {the_plan.name}, "
        f"dt {the_plan.dt:g}"
    )
    print(format_table(summary_rows(scene, met), SUMMARY_HEADER))
    agents = [r for r in records if r.role == "agent"]
    text = f"t = {final.t:g}, wall time {wall:.2f} s"
    if agents and mode.exact:
        text += f", {np.mean([r.rounds_per_second for r in agents]):.1f} rounds/s per agent (mean)"
    print(text)
    for rec in agents:
        if outputs.verbose or rec.dropped_total:
            print(rec.describe())
    for rec in records:  # lockstep: the monitor's last report is the final step's
        if rec.role == "monitor" and (mode.exact or rec.dropped_total):
            print(rec.describe())
    if watcher.ignored:
        print(f"runner: ignored {watcher.ignored} status message(s) not of this run")
    if outputs.save:
        save_final(outputs.save, scene, final, watcher.pose_times())
    if mode.exact and outputs.compare:
        central = prepare(scene, the_plan, distributed=True)
        ref = simulate(
            replace(central, t_end=final.t),
            the_plan.name,
            the_plan.dt,
            samples=[final.t],
            keep_states=False,
            metrics=False,
        )
        assert ref.final is not None  # simulate sets it
        dev = vertex_deviation(
            central.model, ref.final, _as_rep(central.model, scene.model, final)
        )
        print(
            f"lockstep vs centralised simulation (same integrator and dt) at t = {final.t:g}: "
            f"max vertex deviation {dev:.3e}"
        )


#: the exit code of a run that the ensemble's stop service ended before it converged
EXIT_STOPPED_BY_REQUEST = 4


def verdict(scene: Scene, final: State, stop_requested_at: float | None = None) -> int:
    """The scene's convergence verdict on the agents' final state (printed); its exit code.

    A run that someone stopped through the ensemble's stop service (``stop_requested_at``: the
    ensemble's time then) and that has not converged says so, with its own exit code
    (``EXIT_STOPPED_BY_REQUEST``), not that it "did not converge at t_end"."""
    met = ensemble_metrics(scene.model, final)
    converged_at = final.t if met.diameter < scene.tolerance else None
    code, msg = convergence_verdict(scene, met.diameter, converged_at, metrics=met,
                                    components=group_components(scene.model, final))
    if code != 0 and stop_requested_at is not None:
        print(f"stopped by request at t = {final.t:g} (the ensemble's stop service, called at "
              f"t = {stop_requested_at:g}): matching diameter {met.diameter:.3e}, tolerance "
              f"{scene.tolerance:g}")
        return EXIT_STOPPED_BY_REQUEST
    print(msg)
    return code


def _save_partial(plan: RunPlan, outcome: RunOutcome) -> None:
    """The run ended early: save each agent's last state (``partial``), and say so."""
    from .partial import last_state

    assert plan.outputs.save is not None  # only called with --save
    finals = {} if outcome.watcher is None else outcome.watcher.poses
    computed_in = prepare(plan.scene, plan.numerics, distributed=True).model.rotations
    state, times = last_state(plan.scene, finals, outcome.checkpoints, computed_in)
    save_final(plan.outputs.save, plan.scene, state, times, partial=True)


def save_final(path: str, scene: Scene, final: State, times: dict[int, float],
          partial: bool = False) -> None:
    """The agents' final (or, ``partial``, last) poses in the one ``--save`` layout
    (``core.saved``): one sample, each agent's own time."""
    agent_times = np.array([times[a] for a in range(scene.model.n_agents)])
    save_states(path, scene, [final], [ensemble_metrics(scene.model, final)], agent_times,
                partial=partial)
    if partial:
        print(f"partial state saved to {path}: the run ended early; each agent's last state "
              f"(from t = {min(times.values()):g} to {max(times.values()):g}) and its time",
              file=sys.stderr)
    else:
        print(f"final poses (as received on the pose topics) saved to {path}")


def vertex_deviation(model: Model, a: State, b: State) -> float:
    """max over agents and vertices of |x^i_a(a) - x^i_a(b)|."""
    worst = 0.0
    grp = model.rotations
    for g, ga, gb in zip(model.groups, _groups(a), _groups(b)):
        for r in g.reference:
            pa = ga.x + grp.rotate(ga.rot, r)
            pb = gb.x + grp.rotate(gb.rot, r)
            worst = max(worst, float(np.max(np.linalg.norm(pa - pb, axis=1))))
    return worst


def _as_rep(target_model: Model, model: Model, state: State) -> State:
    if type(target_model.rotations) is type(model.rotations):
        return state
    src, dst = model.rotations, target_model.rotations
    return State(
        state.t,
        tuple(
            GroupState(gs.x, dst.from_matrices(src.to_matrices(gs.rot)), gs.v, None)
            for gs in _groups(state)
        ),
    )


def _groups(state: State) -> tuple[GroupState, ...]:
    """The groups of a whole ensemble's state (every one present, none ``None``)."""
    return cast(tuple[GroupState, ...], state.groups)
