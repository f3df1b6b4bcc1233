"""The one NPZ layout of ``--save``: ``polymatch simulate`` (the trajectory at its sample times)
and ``polymatch run`` (the agents' final poses: one sample) write it with ``save_states``,
``load_saved`` reads it. Its keys are listed once, in docs/guide/commands.md ("The --save
file")."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .metrics import EnsembleMetrics, vertices
from .model import GroupState, State
from .scenes.scene import Scene

#: the per-group metrics a saved file holds at each sample (``core.metrics.GroupMetrics``)
GROUP_METRICS = ("centroid_diameter", "rotation_diameter", "matching_diameter", "energy",
                 "orthogonality")


def save_states(path: str | Path, scene: Scene, states: Sequence[State],
                metrics: Sequence[EnsembleMetrics], agent_times: np.ndarray | None = None,
                partial: bool = False) -> None:
    """Write ``states`` (whole states in ``scene``'s representation, one per sample) and
    their ``metrics`` in the one layout; ``agent_times``: each agent's time at the last
    sample, by global agent index (default: the last state's time for every agent)."""
    model = scene.model
    last = states[-1].t
    every = np.full(model.n_agents, last) if agent_times is None else np.asarray(agent_times)
    data: dict[str, Any] = {"times": np.array([s.t for s in states], dtype=float),
                            "origin": np.asarray(scene.origin), "partial": bool(partial),
                            "diameter": np.array([m.diameter for m in metrics])}
    for gi, g in enumerate(model.groups):
        key = f"group{gi}_"
        data[key + "name"] = np.array(g.name)
        data[key + "reference"] = g.reference
        data[key + "edges"] = np.array(g.edges, dtype=int).reshape(-1, 2)
        if g.scales is not None:
            data[key + "scales"] = g.scales
        data[key + "agent_times"] = every[g.start:g.start + g.size].astype(float)
        rows = [_whole(s.groups[gi]) for s in states]
        data[key + "centroids"] = np.array([gs.x + scene.origin for gs in rows])
        data[key + "rotations"] = np.array([model.rotations.to_matrices(gs.rot) for gs in rows])
        for name in GROUP_METRICS:
            data[key + name] = np.array([getattr(m.groups[gi], name) for m in metrics])
    np.savez_compressed(path, **data)


def _whole(gs: GroupState | None) -> GroupState:
    if gs is None:
        raise ValueError("a saved state holds every group")
    return gs


@dataclass(frozen=True)
class SavedGroup:
    """One group of a saved file."""

    name: str
    reference: np.ndarray
    edges: np.ndarray
    scales: np.ndarray | None
    agent_times: np.ndarray
    centroids: np.ndarray
    rotations: np.ndarray
    metrics: dict[str, np.ndarray]

    def vertices(self, sample: int = -1) -> np.ndarray:
        """(n, vertices, d): every agent's vertices at ``sample`` (scaled, if similar)."""
        return vertices(self.centroids[sample], self.rotations[sample], self.reference,
                        self.scales)


@dataclass(frozen=True)
class Saved:
    """A ``--save`` file, read back."""

    times: np.ndarray
    origin: np.ndarray
    partial: bool
    diameter: np.ndarray
    groups: tuple[SavedGroup, ...]

    @property
    def t(self) -> float:
        """The last sample's time (a run: its earliest agent's)."""
        return float(self.times[-1])


def load_saved(path: str | Path) -> Saved:
    """Read a file ``save_states`` wrote."""
    with np.load(path, allow_pickle=False) as data:
        groups = []
        gi = 0
        while f"group{gi}_centroids" in data:
            key = f"group{gi}_"
            groups.append(SavedGroup(
                str(data[key + "name"]), data[key + "reference"], data[key + "edges"],
                data[key + "scales"] if key + "scales" in data else None,
                data[key + "agent_times"], data[key + "centroids"], data[key + "rotations"],
                {name: data[key + name] for name in GROUP_METRICS}))
            gi += 1
        return Saved(data["times"], data["origin"], bool(data["partial"]), data["diameter"],
                     tuple(groups))
