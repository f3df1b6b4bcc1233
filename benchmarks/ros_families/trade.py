"""Speed against accuracy over the ROS node set (lockstep and realtime).

Lockstep: every integrator stage is one message round, so a method's cost is
rounds per step / rounds per second, not right-hand-side evaluations.  For each
integrator and dt the agents' round rate is measured in a real run (8 agent
processes, congruent triangles) and the error is that of the identical
centralised trajectory (lockstep equals it to round-off), as the max vertex error
over the run against a tight reference.

Realtime: each agent steps on its timer with the newest peer poses; the error of
the final poses (each at its own stamp) against the reference, for several step
rates and injected transport delays.
"""

import os
import tempfile
from dataclasses import dataclass

NAME = "trade"
HELP = (
    "speed vs accuracy over ROS: lockstep error and wall per simulated second per integrator; "
    "realtime "
    "error vs rate and delay"
)

SCENE_YAML = """\
name: trade_triangles
description: congruent triangles, D0 < 1 (Theorem 4.2's regime), first order
dimension: 2
seed: 1
model: {order: 1, kappa: 1.0, gamma: 1.0}
integrator: {method: rkmk4, dt: 0.05}
time: {t_end: 4.0}
groups:
  - {name: triangles, shape: triangle, count: 8, centroids: {box: [-6.0, 6.0]}, rotations: {within:
  0.3}}
"""
ROUNDS = 400


def add_arguments(p):
    p.add_argument(
        "--t-end", type=float, default=4.0, help="simulated seconds per run (default 4)"
    )


def _vertex_error_over_run(scene, method, dt, ref):
    import numpy as np

    from polymatch_ros.core.stepping.simulate import simulate

    traj = simulate(scene, method, dt, samples=ref["times"], metrics=False)
    worst = 0.0
    for st, t in zip(traj.states, traj.times):
        k = int(np.argmin(np.abs(ref["times"] - t)))
        if abs(ref["times"][k] - t) > 1e-9:
            continue
        worst = max(worst, float(np.max(np.abs(_verts(scene, st) - ref["verts"][k]))))
    return worst


def _verts(scene, state):
    from polymatch_ros.core.metrics import vertices

    g, gs = scene.model.groups[0], state.groups[0]
    return vertices(gs.x, scene.model.rotations.to_matrices(gs.rot), g.reference)


def _reference(scene, times):
    import numpy as np

    from polymatch_ros.core.stepping.simulate import simulate

    traj = simulate(scene, "adaptive", tolerance=1e-12, samples=np.asarray(times), metrics=False)
    return {"times": np.array(traj.times), "verts": [_verts(scene, st) for st in traj.states]}


LOCKSTEP_CASES = [(m, h) for m in ("lie_euler", "lie_heun", "rkmk4") for h in (0.1, 0.05, 0.025)]
REALTIME_CASES = [(10.0, 0.0), (25.0, 0.0), (50.0, 0.0), (100.0, 0.0), (50.0, 0.05),
                  (50.0, 0.1), (50.0, 0.2)]
TIME_SCALE = 4.0


@dataclass(frozen=True)
class _Setup:
    """What every run of the family shares: the scene (file and loaded), its reference and the
    private ROS environment."""

    quick: bool
    t_end: float
    tmp: str
    path: str
    scene: object
    ref: dict
    env: dict


def _lockstep_row(setup, method, dt, log):
    """One integrator at one dt: its agents' round rate in a real run, its error centrally."""
    import numpy as np

    from polymatch_ros.core.stepping.integrators import METHODS

    from .ros_runs import agent_records, run_cli

    per_step = METHODS[method].info.rounds
    t_run = (40 if setup.quick else ROUNDS) * dt / per_step  # enough rounds for a steady rate
    log(f"lockstep {method} dt = {dt}: {t_run:g} simulated s")
    records = os.path.join(setup.tmp, f"lockstep_{method}_{dt}.jsonl")
    run_cli(setup.env, ["run", setup.path, "--integrator", method, "--dt", str(dt),
                        "--t-end", str(t_run), "--hold", "1e9", "--no-monitor", "--no-compare",
                        "-q", "--run-records", records, "--timeout", "300"], 340)
    rates = [r.rounds_per_second for r in agent_records(records)]
    rps = float(np.mean(rates)) if rates else float("nan")
    wall_per_s = per_step / (dt * rps) if rates else float("nan")
    err = _vertex_error_over_run(setup.scene, method, dt, setup.ref)
    return [method, dt, per_step, f"{rps:.1f}", f"{wall_per_s:.2f}", f"{err:.1e}"]


def _lockstep_table(report, rows, t_end):
    report.table(
        ["integrator", "dt", "rounds/step", "rounds/s (mean of 8 agents)",
         "wall s per simulated s", f"max vertex error over t in [0, {t_end:g}]"],
        rows,
        caption="Lockstep, 8 congruent triangles (D0 < 1), one agent per process, no monitor; "
        f"rates over {ROUNDS} rounds; error against adaptive at tol 1e-12 on 41 sample times",
    )


def _late_share(records):
    """Share of the agents' ticks that started late, '-' without records."""
    ticks = [(r.steps, r.late_ticks) for r in records]
    if not ticks:
        return "-"
    return f"{sum(b for _, b in ticks) / max(1, sum(a for a, _ in ticks)):.0%}"


def _final_pose_error(scene, npz):
    """Max vertex error of each agent's saved final pose against the reference at its stamp."""
    import numpy as np

    from polymatch_ros.core.saved import load_saved

    saved = load_saved(npz).groups[0]
    times = saved.agent_times
    agent_ref = _reference(scene, np.unique(np.append(times, 0.0)))
    got = saved.vertices()
    err = 0.0
    for i, t in enumerate(times):
        k = int(np.argmin(np.abs(agent_ref["times"] - t)))
        want = agent_ref["verts"][k][i] + scene.origin
        err = max(err, float(np.max(np.abs(got[i] - want))))
    return err


def _realtime_row(setup, rate, delay, log):
    """One realtime run at ``rate`` Hz with ``delay`` s injected: late ticks and final error."""
    from .ros_runs import agent_records, run_cli

    log(f"realtime rate {rate:g} Hz, delay {delay:g} s")
    npz = os.path.join(setup.tmp, f"rt_{rate}_{delay}.npz")
    records = os.path.join(setup.tmp, f"rt_{rate}_{delay}.jsonl")
    out = run_cli(setup.env, ["run", setup.path, "--mode", "realtime", "--rate", str(rate),
                              "--time-scale", str(TIME_SCALE), "--delay", str(delay),
                              "--t-end", str(setup.t_end), "--hold", "1e9", "--no-monitor",
                              "-q",
                              "--run-records", records, "--save", npz, "--timeout", "200"], 240)
    late = _late_share(agent_records(records))
    if not os.path.exists(npz):
        return [rate, TIME_SCALE / rate, delay, "-", "-",
                "run failed: " + out.stderr.strip()[-80:]]
    err = _final_pose_error(setup.scene, npz)
    return [rate, f"{TIME_SCALE / rate:g}", delay, f"{delay * TIME_SCALE:g}", late, f"{err:.1e}"]


def _realtime_table(report, rows, t_end):
    report.table(
        ["rate (Hz)", "dt (simulated s)", "injected delay (wall s)", "delay (simulated s)",
         "ticks started late", "max vertex error at the agents' final stamps"],
        rows,
        caption=f"Realtime, 8 congruent triangles (D0 < 1), time scale {TIME_SCALE:g}, "
        f"rkmk4 per tick, t_end {t_end:g}; each agent's final pose against the reference at "
        "its own stamp",
    )


def _notes(report):
    report.text(
        "- Lockstep equals the centralised trajectory to round-off, so its error is the method's; "
        "its cost is rounds: a 4-stage method pays 4 rounds per step.",
        "- Realtime errors combine the step, the stale peer poses (one tick or more) and "
        "the delay. A peer's pose is a tick old, so the error is first order in the tick (dt) "
        "however accurate the per-tick method, until the processes cannot keep the rate: "
        "'ticks started late' counts ticks that began more than one period behind schedule "
        "(a late agent then steps in a burst on stale poses).",
    )


def run(args, log):
    from dataclasses import replace

    import numpy as np
    from domain_coordinator import domain_id

    from polymatch_ros.core.scenes.scene import load_scene
    from polymatch_ros.ros.network.environment import private_ros_environment

    from ..report import Report
    from .ros_runs import write_scene

    report = Report(NAME, "Speed against accuracy over the ROS node set "
                          "(`python -m benchmarks trade`)")
    t_end = 0.5 if args.quick else args.t_end
    methods = [("rkmk4", 0.1)] if args.quick else LOCKSTEP_CASES
    cases = [(50.0, 0.0)] if args.quick else REALTIME_CASES
    with tempfile.TemporaryDirectory() as tmp, domain_id() as dom:
        path = write_scene(tmp, "trade_triangles.yaml", SCENE_YAML)
        scene = replace(load_scene(path), t_end=t_end)
        setup = _Setup(args.quick, t_end, tmp, path, scene,
                       _reference(scene, np.linspace(0.0, t_end, 41)),
                       private_ros_environment(dom))
        _lockstep_table(report, [_lockstep_row(setup, m, dt, log) for m, dt in methods], t_end)
        _realtime_table(report, [_realtime_row(setup, r, d, log) for r, d in cases], t_end)
    _notes(report)
    return report
