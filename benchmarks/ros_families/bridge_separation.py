"""Robots that share a room: formation, minimum separation and differential-drive bases, measured
from the simulated robots' logged true poses (the rows `python -m benchmarks bridge` adds).

For each configuration (first order, second order, first order on unicycle bases; with and
without the safety filter) and each of ``--starts`` random starts of 8 robots (discs of radius
r, no two closer than 2 r + 0.1 at the start), ``polymatch run --mode bridge --robot-log DIR``
drives the robots to a circle formation (radius 2 m, places 1.53 m apart, 2 r = 0.6 m) for
``--separation-t-end`` wall seconds without noise, and the benchmark reads the logs:

  min distance   the smallest distance between two robots' true positions (axles) over the run
  reached        the formation error max_ij |(q_i - c_i) - (q_j - c_j)| below the tolerance
                 (0.05 m) from some time to the end, q the robot's position (unicycle: the point
                 ahead of its axle), and from when (s after the first motion)
  heading spread the shortest arc holding every robot's final heading (unicycle bases)
"""

import tempfile

import numpy as np

RADIUS, ALPHA, CIRCLE, TOLERANCE, AXLE = 0.3, 2.0, 2.0, 0.05, 0.2
#: the robots' bounds, the same with and without the filter (the filter's discs of what a peer
#: can travel come from them): speed (m/s), turn rate (rad/s), acceleration (m/s^2)
SPEED, TURN, ACCEL = 1.0, 4.0, 3.0
ALPHA_SECOND = 3.0  # the second-order barrier's rate (both poles of h'' + 2 a h' + a^2 h)
CONFIGS = (  # (label, model order, drive)
    ("first order", 1, "holonomic"),
    ("second order", 2, "holonomic"),
    ("unicycle, first order", 1, "unicycle"),
)


def starts(count, n=8, box=4.0, gap=2 * (RADIUS + AXLE) + 0.1, seed=0):
    """``count`` arrays (n, 2) of start positions in [-box, box]^2, no two closer than ``gap``
    (the unicycles' discs of r + ell around the points ahead apart too)."""
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < count:
        p = rng.uniform(-box, box, (n, 2))
        d = np.linalg.norm(p[:, None] - p[None], axis=2) + np.eye(n) * 1e9
        if d.min() >= gap:
            out.append(p)
    return out


def scene_text(order, points, filtered, seed):
    """A scene of 8 triangles (0.3 m) at ``points`` with a circle formation (and safety)."""
    model = "{order: 1, kappa: 1.0, gamma: 1.0}" if order == 1 else \
        "{order: 2, kappa: 1.0, gamma: 2.0, mass: 1.0}"
    alpha = ALPHA if order == 1 else ALPHA_SECOND
    safety = f"safety: {{radius: {RADIUS}, alpha: {alpha}}}\n" if filtered else ""
    rows = ", ".join(f"[{x:.6f}, {y:.6f}]" for x, y in points)
    return (f"name: separation\ndimension: 2\nseed: {seed}\nmodel: {model}\n"
            f"integrator: {{method: rkmk4, dt: 0.05}}\ntime: {{t_end: 60.0}}\n"
            f"convergence: {{tolerance: {TOLERANCE}}}\nformation: {{circle: {CIRCLE}}}\n{safety}"
            f"groups:\n  - {{name: robots, shape: triangle, size: 0.3, count: {len(points)}, "
            f"centroids: {{points: [{rows}]}}}}\n")


def log_figures(logs, offsets, ell, t_end):
    """(min distance, reached-from time or None, final heading spread) of one run's logs."""
    from scipy.spatial.transform import Rotation

    from polymatch_ros.core.robots.unicycle import heading_spread

    from .bridge import first_motion

    start = first_motion(logs)
    end = min(start + t_end, min(data[-1, 0] for data in logs.values()))
    times = np.arange(start, end, 1.0 / 30.0)
    n = len(offsets)
    pos = np.empty((len(times), n, 2))
    head = np.empty((len(times), n))
    for a in range(n):
        data = logs[a]
        k = np.clip(np.searchsorted(data[:, 0], times, side="right") - 1, 0, len(data) - 1)
        pos[:, a] = data[k, 1:3]
        mats = Rotation.from_quat(data[k, 4:8]).as_matrix()
        head[:, a] = np.arctan2(mats[:, 1, 0], mats[:, 0, 0])
    diff = pos[:, :, None] - pos[:, None]
    dist = np.linalg.norm(diff, axis=3) + np.eye(n) * 1e9
    ahead = pos + ell * np.stack([np.cos(head), np.sin(head)], axis=2)
    y = ahead - offsets[None]
    err = np.max(np.linalg.norm(y[:, :, None] - y[:, None], axis=3), axis=(1, 2))
    above = np.flatnonzero(err >= TOLERANCE)
    reached = float(times[0]) if not len(above) else (
        float(times[above[-1] + 1]) if above[-1] + 1 < len(times) else None)
    return (float(dist.min()), None if reached is None else reached - start,
            heading_spread(head[-1]), float(err[-1]))


def one_run(env, workdir, case, t_end):
    """Figures of one start: (min distance, reached, heading spread, final error) or a reason."""
    from polymatch_ros.core.scenes.scene import load_scene

    from .bridge import read_robot_logs
    from .ros_runs import run_cli, write_scene

    (label, order, drive), filtered, k, points = case
    logs = tempfile.mkdtemp(prefix=f"sep_{order}_{drive}_{int(filtered)}_{k}_", dir=workdir)
    path = write_scene(logs, "scene.yaml", scene_text(order, points, filtered, k))
    out = run_cli(env, ["run", path, "--mode", "bridge", "--rate", "20", "--lag", "0.05",
                        "--t-end", repr(t_end), "--hold", "1e9", "--ensemble", "bench_sep",
                        "--drive", drive, "-q", "--robot-log", logs,
                        "--max-linear-speed", repr(SPEED), "--max-angular-speed", repr(TURN),
                        "--max-linear-accel", repr(ACCEL),
                        "--timeout", repr(t_end + 120.0)], t_end + 160.0)
    got = read_robot_logs(logs, len(points))
    if len(got) < len(points):
        return f"{len(got)} robot logs (exit code {out.returncode})"
    offsets = load_scene(path).formation
    return log_figures(got, offsets, AXLE if drive == "unicycle" else 0.0, t_end)


def run_separation(env, workdir, count, t_end, log, filters=(True, False)):
    """{(config, filtered): [figures or reason per start]} over ``count`` starts, with the
    safety filter on and/or off (``filters``)."""
    found = {}
    points = starts(count)
    for config in CONFIGS:
        for filtered in filters:
            runs = []
            for k, p in enumerate(points):
                log(f"{config[0]}, filter {'on' if filtered else 'off'}, start {k + 1}/{count}")
                runs.append(one_run(env, workdir, (config, filtered, k, p), t_end))
            found[(config, filtered)] = runs
    return found


def _summary(runs):
    ok = [r for r in runs if not isinstance(r, str)]
    if not ok:
        return ["-"] * 6 + [f"{len(runs)} failed"]
    dmin = np.array([r[0] for r in ok])
    reached = [r[1] for r in ok if r[1] is not None]
    below = int(np.sum(dmin < 2 * RADIUS))
    when = "-" if not reached else f"{np.median(reached):.1f} / {max(reached):.1f}"
    return [f"{dmin.min():.3f}", f"{np.median(dmin):.3f}", f"{below} of {len(ok)}",
            f"{len(reached)} of {len(ok)}", when, f"{np.median([r[3] for r in ok]):.1e}",
            f"{np.median([r[2] for r in ok]):.2f}" + (f"; {len(runs) - len(ok)} failed"
                                                      if len(ok) < len(runs) else "")]


def separation_table(report, found, count, t_end):
    rows = [[config[0], "on" if filtered else "off"] + _summary(found[(config, filtered)])
            for config in CONFIGS for filtered in (True, False) if (config, filtered) in found]
    report.table(
        ["robots", "safety filter", "min distance (m)", "median of run minima (m)",
         f"runs below 2 r = {2 * RADIUS:g}", f"formation reached (< {TOLERANCE:g} m)",
         "reached from (s): median / max", "final formation error (median, m)",
         "final heading spread (median, rad)"],
        rows,
        caption=f"8 simulated robots (discs of r = {RADIUS:g} m; alpha = {ALPHA:g}/s), circle "
        f"formation of radius {CIRCLE:g} m, {count} random starts each, {t_end:g} s per run, "
        f"agents at 20 Hz, lag 0.05 s, no noise; from the robots' logged true poses")
