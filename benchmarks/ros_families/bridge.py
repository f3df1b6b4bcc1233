"""Matching error of the bridge loop against pose noise and actuator lag.

What precision can a robot team driven by polymatch expect?  For each noise level sigma
(position noise sigma m and angle noise sigma rad, the same number) and actuator time constant
(lag), ``polymatch run SCENE --mode bridge --robot-log DIR`` drives 8 simulated robots on the
Fig. 1 scene (congruent triangles, first-order model (A-2), Theorem 4.2) for ``--t-end`` wall
seconds; each robot writes its true and its measured pose at every step (30 Hz).  From these
logs, sampled on a common clock (each robot's latest step), the benchmark computes two
matching diameters max_{i,j,a} |x^i_a - x^j_a|:

  measured  of the noisy poses the agents act on (what the monitor reports),
  true      of the robots' actual poses (what a robot team achieves),

and reports them over the last ``--window`` seconds of the run (median and max) beside the
noise floor ``core.robots.robot_commands.noise_floor`` (6 sqrt(2) (sigma sqrt(d) + sigma r_max),
the
measured diameter noise alone makes) and the time, from the robots' first motion, after which
each stays below it.  A second table varies the agents' rate at one noise level and lag.
Time starts at the first robot motion; every run has its own domain id and a timeout.

A run counts only if every agent drove its robot to t_end (its run record's last measured-pose
stamp); one that did not is run again (``--retries``) and listed under the tables.
"""

import os
import tempfile

NAME = "bridge"
HELP = ("bridge loop: true and measured matching diameter of simulated robots vs pose noise "
        "and actuator lag")

QUICK_SCENE = """\
name: bridge_quick
dimension: 2
seed: 1
model: {order: 1}
integrator: {method: rkmk4, dt: 0.05}
time: {t_end: 1.0}
groups:
  - {name: triangles, shape: triangle, count: 2, centroids: {box: [-0.5, 0.5]},
     rotations: {within: 0.3}}
"""


def add_arguments(p):
    from ..options import add_number, float_list

    p.add_argument("--scene", default="congruent_triangles",
                   help="scene file or shipped scene (default congruent_triangles, Fig. 1)")
    p.add_argument("--noise", type=float_list(0.0), default=[0.0, 0.001, 0.005, 0.02],
                   metavar="S,S,...", help="position (m) and angle (rad) noise sigmas "
                   "(default 0,0.001,0.005,0.02)")
    p.add_argument("--lag", type=float_list(0.0), default=[0.02, 0.1, 0.3], metavar="T,T,...",
                   help="actuator time constants, s (default 0.02,0.1,0.3)")
    p.add_argument("--rates", type=float_list(0.1), default=[5.0, 10.0, 20.0],
                   metavar="HZ,HZ,...", help="agent rates of the rate table (default 5,10,20)")
    add_number(p, "--rate-noise", 0.0, 0.005, "sigma of the rate table", float)
    add_number(p, "--rate-lag", 0.0, 0.1, "lag of the rate table, s", float)
    add_number(p, "--rate", 0.1, 50.0, "agent rate of the noise x lag grid, Hz", float)
    add_number(p, "--t-end", 1.0, 16.0, "wall seconds per run", float)
    add_number(p, "--window", 0.1, 4.0, "steady-state window: the last W seconds", float)
    add_number(p, "--retries", 0, 1, "runs again a case whose run gave no figures", int)
    add_number(p, "--starts", 0, 20, "random starts per row of the separation table "
               "(formation, safety filter, unicycle bases; 0: no such table)", int)
    add_number(p, "--separation-t-end", 1.0, 25.0, "wall seconds per separation run", float)
    p.add_argument("--separation-filter", choices=("both", "on", "off"), default="both",
                   help="the separation table's rows with the safety filter, without, or both "
                   "(default both)")
    p.add_argument("--separation-only", action="store_true",
                   help="only the separation table (not the noise x lag grid)")


# -- reading the robots' logs --------------------------------------------------------------------
def read_robot_logs(directory, n_agents):
    """{agent: array (steps, 15)} of the pose logs (``robot.POSE_LOG_COLUMNS``) found."""
    import numpy as np

    from polymatch_ros.ros.supervisor.bridge_run import robot_log

    logs = {}
    for a in range(n_agents):
        path = robot_log(directory, a)
        if os.path.exists(path):
            data = np.loadtxt(path, ndmin=2)
            if len(data):
                logs[a] = data
    return logs


def first_motion(logs):
    """Wall time of the first step at which any robot's true pose changed."""
    import numpy as np

    starts = []
    for data in logs.values():
        moved = np.flatnonzero(np.any(np.diff(data[:, 1:8], axis=0) != 0.0, axis=1))
        if len(moved):
            starts.append(data[moved[0] + 1, 0])
    return min(starts) if starts else None


def diameters(model, logs, times, measured=False):
    """Matching diameter of the logged poses at each wall time of ``times`` (each robot's
    latest step at or before it; true or measured poses)."""
    import numpy as np
    from scipy.spatial.transform import Rotation

    from polymatch_ros.core.metrics import ensemble_metrics
    from polymatch_ros.core.model import GroupState, State

    cols = slice(8, 15) if measured else slice(1, 8)
    d, grp = model.dim, model.rotations
    out = np.empty(len(times))
    per_agent = {}
    for a, data in logs.items():
        k = np.clip(np.searchsorted(data[:, 0], times, side="right") - 1, 0, len(data) - 1)
        pose = data[k, cols]
        per_agent[a] = (pose[:, :d], Rotation.from_quat(pose[:, 3:7]).as_matrix()[:, :d, :d])
    for i in range(len(times)):
        groups = []
        for g in model.groups:
            x = np.array([per_agent[a][0][i] for a in g.indices])
            mats = np.array([per_agent[a][1][i] for a in g.indices])
            groups.append(GroupState(x, grp.from_matrices(mats)))
        out[i] = ensemble_metrics(model, State(float(times[i]), tuple(groups))).diameter
    return out


def below_from(times, values, level):
    """The first time from which ``values`` stay below ``level`` to the end, or None."""
    import numpy as np

    above = np.flatnonzero(values >= level)
    if not len(above):
        return float(times[0])
    return float(times[above[-1] + 1]) if above[-1] + 1 < len(times) else None


# -- one run -------------------------------------------------------------------------------------
def _bridge_run(env, scene_path, case, t_end, workdir):
    """``polymatch run --mode bridge`` of one case (sigma, lag, rate): (log dir, the agents'
    run records, the runner's error or None)."""
    from polymatch_ros.ros.wire import run_records

    from .ros_runs import run_cli

    sigma, lag, rate = case
    logs = tempfile.mkdtemp(prefix=f"s{sigma:g}_l{lag:g}_r{rate:g}_", dir=workdir)
    records = os.path.join(logs, "records.jsonl")
    out = run_cli(env, ["run", scene_path, "--mode", "bridge", "--rate", repr(rate),
                     "--lag", repr(lag), "--position-noise", repr(sigma),
                     "--angle-noise", repr(sigma), "--t-end", repr(t_end), "--hold", "1e9",
                     "--ensemble", "bench_bridge", "-q", "--run-records", records,
                     "--robot-log", logs, "--timeout", repr(t_end + 120.0)], t_end + 160.0)
    errors = [line for line in out.stderr.splitlines() if line.startswith("polymatch: error:")]
    # 3: the measured diameter was not under the tolerance at t_end (a short run, no noise)
    error = None if out.returncode in (0, 3) else (
        errors[-1] if errors else f"exit code {out.returncode}")
    agents = []
    if os.path.exists(records):
        with open(records, encoding="utf-8") as fh:
            agents = [r for r in run_records(fh) if r.role == "agent"]
    return logs, agents, error


def _driven(agents, n_agents, t_end, rate):
    """(seconds every agent drove its robot: the smallest last measured-pose stamp, share of
    ticks started late, why the run has no figures or None)."""
    if len(agents) < n_agents:
        return None, None, f"{len(agents)} of {n_agents} agents' run records"
    ran = min(r.t for r in agents)
    steps = sum(r.steps for r in agents)
    late = sum(r.late_ticks for r in agents) / steps if steps else None
    if ran < t_end - max(0.5, 2.0 / rate):  # its measured poses stopped coming
        return ran, late, f"an agent drove its robot only up to t = {ran:.1f} s"
    return ran, late, None


def measure(scene, scene_path, case, t_end, window, env, workdir):
    """Figures of one case: noise floor, measured and true diameters over the window,
    times below the floor; ``failure`` says why there are none (``error``: the runner's)."""
    import numpy as np

    from polymatch_ros.ros.supervisor.plan import scene_noise_floor

    sigma, n = case[0], scene.model.n_agents
    logs_dir, agents, error = _bridge_run(env, scene_path, case, t_end, workdir)
    ran, late, failure = _driven(agents, n, t_end, case[2])
    got = {"floor": scene_noise_floor(scene, sigma, sigma), "late": late, "span": ran,
           "error": error, "failure": failure}
    logs = read_robot_logs(logs_dir, n)
    start = first_motion(logs)
    if failure or len(logs) < n or start is None:
        got["failure"] = failure or error or f"{len(logs)} robot logs, no motion"
        return got
    end = min(start + t_end, min(data[-1, 0] for data in logs.values()))
    times = np.arange(start, end, 1.0 / 30.0)
    level = max(got["floor"], scene.tolerance)  # the run's tolerance (plan.bridge_scene)
    in_window = times >= end - window
    for kind in ("measured", "true"):
        values = diameters(scene.model, logs, times, measured=kind == "measured")
        got[kind] = (float(np.median(values[in_window])), float(np.max(values[in_window])))
        below = below_from(times, values, level)
        got[kind + "_below"] = None if below is None else below - start
    return got


def measure_with_retries(scene, scene_path, case, timing, env, workdir, retries, log):
    """``measure``, again up to ``retries`` times while a run gives no figures; (figures,
    notes on the failed attempts and on runner errors of kept runs)."""
    t_end, window = timing
    notes = []
    for attempt in range(retries + 1):
        got = measure(scene, scene_path, case, t_end, window, env, workdir)
        what = f"sigma {case[0]:g}, lag {case[1]:g}, rate {case[2]:g}, run {attempt + 1}"
        if "true" in got:
            if got["error"]:
                notes.append(f"{what}: figures kept (the agents drove to t_end), "
                             f"but {got['error']}")
            return got, notes
        notes.append(f"{what}: no figures: {got['failure']}")
        log(notes[-1])
    return got, notes


# -- the report ----------------------------------------------------------------------------------
def _fmt_time(value):
    return "-" if value is None else f"{value:.1f}"


def _row(got):
    """Table cells after the case's own: floor, measured, true, times below, late ticks."""
    if "true" not in got:
        return [f"{got['floor']:.2e}", "-", "-", "-", "-", "-", "-",
                "-", "failed: " + str(got["failure"])[-60:]]
    floor, (m_med, m_max), (t_med, t_max) = got["floor"], got["measured"], got["true"]
    ratio = (lambda v: f"{v / floor:.2f}") if floor > 0 else (lambda v: "-")  # noqa: E731
    late = "-" if got["late"] is None else f"{got['late']:.0%}"
    return [f"{floor:.2e}", f"{m_med:.2e} / {m_max:.2e}", ratio(m_med),
            f"{t_med:.2e} / {t_max:.2e}", ratio(t_med),
            _fmt_time(got["measured_below"]), _fmt_time(got["true_below"]),
            f"{got['span']:.1f}", late]


HEADER = ["noise floor", "measured: median / max", "measured / floor", "true: median / max",
          "true / floor", "measured below floor from (s)", "true below floor from (s)",
          "run (s)", "ticks late"]


def _exponents(found, noises, lags):
    """Rows (lag, p measured, p true) of least-squares fits diameter ~ sigma^p over sigma > 0."""
    import numpy as np

    rows = []
    for lag in lags:
        pts = [(s, found[(s, lag)]) for s in noises if s > 0 and "true" in found[(s, lag)]]
        if len(pts) < 2:
            continue
        x = np.log([s for s, _ in pts])
        fit = [np.polyfit(x, np.log([g[kind][0] for _, g in pts]), 1)[0]
               for kind in ("measured", "true")]
        rows.append([lag, f"{fit[0]:.2f}", f"{fit[1]:.2f}"])
    return rows


def _model_alone(scene, t_end, window):
    """Median matching diameter of (A-2) itself (no noise, no lag) over the window."""
    import numpy as np

    from polymatch_ros.core.stepping.simulate import simulate

    samples = np.linspace(max(0.0, t_end - window), t_end, 9)
    traj = simulate(scene, "rkmk4", 0.01, samples=samples)
    return float(np.median(traj.diameters))


def _plan(args):
    """(scene path or None for the quick scene, grid cases, rate cases, t_end, window)."""
    if args.quick:
        return None, [(0.005, 0.1, 50.0)], [], 0.5, 0.2
    if args.separation_only:
        return args.scene, [], [], args.t_end, args.window
    grid = [(s, lag, args.rate) for s in args.noise for lag in args.lag]
    rates = [(args.rate_noise, args.rate_lag, r) for r in args.rates]
    return args.scene, grid, rates, args.t_end, args.window


def run(args, log):
    from domain_coordinator import domain_id

    from polymatch_ros.core.errors import PolymatchError
    from polymatch_ros.core.scenes.scene import resolve_scene_path
    from polymatch_ros.ros.network.environment import private_ros_environment

    from ..report import Report

    report = Report(NAME, "Robots that share a room: separation, formation and differential-drive "
                    "bases (`python -m benchmarks bridge --separation-only`)"
                    if args.separation_only else "Robots in the loop: matching error against "
                    "pose noise and actuator lag (`python -m benchmarks bridge`)")
    scene_arg, grid, rates, t_end, window = _plan(args)
    scene_path = None if scene_arg is None else os.path.abspath(resolve_scene_path(scene_arg))
    found, notes = {}, []
    with tempfile.TemporaryDirectory(prefix="bench_bridge_") as workdir, domain_id() as dom:
        scene, scene_path = _scene(scene_path, t_end, workdir)
        env = private_ros_environment(dom)
        for case in grid + rates:
            if case not in found:
                log(f"sigma {case[0]:g}, lag {case[1]:g} s, rate {case[2]:g} Hz: "
                    f"{t_end:g} s of robots")
                found[case], more = measure_with_retries(
                    scene, scene_path, case, (t_end, window), env, workdir, args.retries, log)
                notes += more
        starts = 0 if args.quick else args.starts
        if starts:
            from .bridge_separation import run_separation, separation_table

            filters = {"both": (True, False), "on": (True,), "off": (False,)}
            separated = run_separation(env, workdir, starts, args.separation_t_end, log,
                                       filters[args.separation_filter])
            separation_table(report, separated, starts, args.separation_t_end)
    if not grid:
        return report
    if all("true" not in got for got in found.values()):
        raise PolymatchError(f"bridge: no run gave figures ({notes[0]})")
    _tables(report, scene, grid, rates, found, (t_end, window, _model_alone(scene, t_end,
                                                                             window)))
    if notes:
        report.text("Runs without figures, and runner errors:", *[f"- {f}" for f in notes])
    return report


def _scene(scene_path, t_end, workdir):
    """(scene with ``t_end``, its path); the quick scene, written to ``workdir``, if None."""
    from dataclasses import replace

    from polymatch_ros.core.robots.robot_commands import bridge_model
    from polymatch_ros.core.scenes.scene import load_scene

    if scene_path is None:
        scene_path = os.path.join(workdir, "bridge_quick.yaml")
        with open(scene_path, "w", encoding="utf-8") as fh:
            fh.write(QUICK_SCENE)
    scene = replace(load_scene(scene_path), t_end=t_end)
    bridge_model(scene.model)  # a scene bridge mode refuses: one line before any run
    return scene, scene_path


def _tables(report, scene, grid, rates, found, timing):
    t_end, window, alone = timing
    robots = f"{scene.name}, {scene.model.n_agents} simulated robots (30 Hz)"
    report.table(["sigma (m, rad)", "lag (s)"] + HEADER,
                 [[s, lag] + _row(found[(s, lag, r)]) for s, lag, r in grid],
                 caption=f"{robots}, agents at {grid[0][2]:g} Hz, {t_end:g} s per run; "
                 f"diameters over the last {window:g} s of the run")
    fits = _exponents({(s, lag): found[(s, lag, r)] for s, lag, r in grid},
                      sorted({c[0] for c in grid}), sorted({c[1] for c in grid}))
    if fits:
        report.table(["lag (s)", "measured ~ sigma^p: p", "true ~ sigma^p: p"], fits,
                     caption="Scaling with the noise: least-squares exponent over sigma > 0 of "
                     "the median diameters (the noise floor formula: p = 1)")
    if rates:
        report.table(["rate (Hz)", "sigma (m, rad)", "lag (s)"] + HEADER,
                     [[r, s, lag] + _row(found[(s, lag, r)]) for s, lag, r in rates],
                     caption=f"{robots}, against the agents' rate, {t_end:g} s per run")
    report.text(
        "- true: the diameter of the robots' actual poses (their `pose_log`); measured: of the "
        "noisy poses the agents act on. Both sampled every 1/30 s, each robot at its latest "
        "step; times count from the first robot motion.",
        "- noise floor: `core.robots.robot_commands.noise_floor`, 6 sqrt(2) (sigma sqrt(d) + "
        "sigma r_max), "
        "the measured diameter noise alone makes (the tolerance of a bridge run); with "
        "sigma = 0 the scene's tolerance. 'below floor from': the time after which the "
        "diameter stays below it to the end ('-': not by the end). 'run': how long every "
        "agent drove its robot (the smallest last measured-pose stamp); 'ticks late': share of "
        "the agents' ticks that started more than one period late (the machine's load).",
        f"- (A-2) alone (no noise, no lag; rkmk4, dt 0.01) has median diameter {alone:.1e} "
        "over the same window: a diameter far above it is what noise and lag leave, not the "
        "run's length.",
    )
