"""The tables of `polymatch bench lossy`, built from run records (``wire.RunRecord``) alone.

Pure functions of the data the runs left (monitor records from the status topic, the hosts'
``--records`` files, the saved final poses), so they are tested without network namespaces.
"""

from dataclasses import dataclass, field

import numpy as np

REALTIME_HEADER = ["loss %", "delay s", "converged", "time to tolerance (sim. s)",
                   "vs centralised", "final diameter", "late ticks", "packets dropped"]
LOCKSTEP_HEADER = ["loss %", "rounds/s per agent (mean)", "vs 0 % loss",
                   "max vertex deviation from centralised", "packets dropped", "wall s"]


@dataclass
class RealtimeCell:
    """One realtime run: its settings and what the records say."""

    loss: float
    delay: float
    exit_code: int
    monitor: list = field(default_factory=list)     # the monitor's status records, in order
    agents: list = field(default_factory=list)      # the agents' final records (every host)
    dropped: int = 0                                # packets the loss rules dropped
    failure: str = ""


@dataclass
class LockstepCell:
    loss: float
    agents: list = field(default_factory=list)
    deviation: float = None
    dropped: int = 0
    wall: float = 0.0
    failure: str = ""


def time_to_tolerance(records, n_agents, tolerance):
    """The simulated time from which every monitor report of all ``n_agents`` stayed under
    ``tolerance`` (None if the last such report is not under it)."""
    full = [r for r in records if r.agents_heard == n_agents and r.diameter is not None]
    if not full or not full[-1].diameter < tolerance:
        return None
    first = len(full) - 1
    while first > 0 and full[first - 1].diameter < tolerance:
        first -= 1
    return full[first].t


def final_diameter(records, n_agents):
    """The diameter of the last monitor report that heard all ``n_agents`` (None if none)."""
    full = [r for r in records if r.agents_heard == n_agents and r.diameter is not None]
    return full[-1].diameter if full else None


def realtime_row(cell, n_agents, tolerance, central_time):
    """A row of REALTIME_HEADER; ``central_time``: the centralised run's time to tolerance."""
    if cell.failure:
        return [f"{cell.loss:g}", f"{cell.delay:g}", f"failed: {cell.failure}"] + ["-"] * 5
    reached = time_to_tolerance(cell.monitor, n_agents, tolerance)
    diameter = final_diameter(cell.monitor, n_agents)
    converged = cell.exit_code == 0 and reached is not None
    late = sum(r.late_ticks for r in cell.agents)
    ticks = sum(r.steps for r in cell.agents)
    return [f"{cell.loss:g}", f"{cell.delay:g}", "yes" if converged else "no",
            f"{reached:.2f}" if converged else "not reached",
            f"{reached / central_time:.2f}x" if converged and central_time else "-",
            "-" if diameter is None else f"{diameter:.2e}",
            f"{late} of {ticks}" if ticks else "-", str(cell.dropped)]


def mean_rate(cell):
    rates = [r.rounds_per_second for r in cell.agents if r.role == "agent" and r.finished]
    return float(np.mean(rates)) if rates else None


def lockstep_rows(cells):
    """Rows of LOCKSTEP_HEADER; the rate ratio is against the cell with 0 % loss (if any)."""
    base = next((mean_rate(c) for c in cells if c.loss == 0 and not c.failure), None)
    rows = []
    for cell in cells:
        rate = None if cell.failure else mean_rate(cell)
        if rate is None:
            rows.append([f"{cell.loss:g}", f"failed: {cell.failure or 'no agent records'}"]
                        + ["-"] * 4)
            continue
        rows.append([f"{cell.loss:g}", f"{rate:.1f}",
                     f"{rate / base:.2f}" if base else "-",
                     "-" if cell.deviation is None else f"{cell.deviation:.1e}",
                     str(cell.dropped), f"{cell.wall:.1f}"])
    return rows


def saved_vertices(scene, path):
    """(t, [vertices of group g: (n_g, n_a, d)]) of the final poses a run saved (--save)."""
    from ..core.metrics import vertices

    data = np.load(path)
    out = [vertices(data[f"group{gi}_centroids"], data[f"group{gi}_rotations"], g.reference)
           for gi, g in enumerate(scene.model.groups)]
    return float(data["t"]), out


def central_deviation(scene, path):
    """Max vertex deviation of the saved final poses from the centralised simulation with the
    same integrator and step, run here to the same t (lockstep equals it to round-off)."""
    from dataclasses import replace

    from ..core.metrics import vertices
    from ..core.simulate import plan, simulate

    t, got = saved_vertices(scene, path)
    method = plan(scene, None, None, distributed=True).name
    sc = replace(scene, t_end=t)
    traj = simulate(sc, method, sc.integrator.dt, samples=[t], metrics=False)
    model = traj.scene.model            # the representation the simulation ran in
    want = [vertices(gs.x + scene.origin, model.rotations.to_matrices(gs.rot), g.reference)
            for g, gs in zip(model.groups, traj.final.groups)]
    return max(float(np.max(np.linalg.norm(a - b, axis=-1))) for a, b in zip(got, want))
