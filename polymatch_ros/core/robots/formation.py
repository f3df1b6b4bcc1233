"""Formations: each agent's centroid is driven to its own place c_i instead of one common point.

Consensus on y_i = xbar_i - c_i.  The offsets are constant, so y_i' = xbar_i' and the model's
centroid equations hold for y unchanged: Proposition 2.1's closed form becomes

    first order   xbar_i(t) = c_i + ybar + exp(-kappa t / gamma) (xbar_i(0) - c_i - ybar),

ybar the mean of y_i(0) (second order: the same oscillator on y), and every bound on the
matching diameter of y (Theorem 4.2, the certificate) is a bound on the formation error.  The
scene stores y (``Scene.initial`` and every state a run carries are formation coordinates);
``positions`` turns them back into where the centroids are.

The offsets are fixed in the world frame; they do not turn with the ensemble's common
orientation (docs/guide/robots.md, Formations, gives the reason).

Scene key (one of):

    formation: {offsets: [[x, y], ...]}        # one per agent, in agent order
    formation: {circle: 2.0}                   # agents evenly on a circle (first two axes)
    formation: {groups: {name: [x, y], ...}}   # one offset per group (added to the above)
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import SceneError
from ..scenes.checks import Map, describe, matrix_rows, number, vector
from ..scenes.limits import MAX_LENGTH

FORMATION_KEYS = ("offsets", "circle", "groups")


def parse_formation(raw: object, dim: int, sizes: dict[str, tuple[int, int]],
                    path: str = "formation") -> np.ndarray:
    """The offsets (N, d) of a scene's ``formation`` key; ``sizes`` maps each group's name to
    (start, size) in agent order."""
    fm = Map(raw, path, FORMATION_KEYS)
    n = sum(size for _, size in sizes.values())
    if not (fm.has("offsets") or fm.has("circle") or fm.has("groups")):
        raise SceneError(f"{path}: give offsets (one per agent), circle (a radius) or groups")
    if fm.has("offsets") and fm.has("circle"):
        raise SceneError(f"{path}: give offsets or circle, not both")
    offsets = np.zeros((n, dim))
    if fm.has("offsets"):
        offsets = matrix_rows(fm.raw("offsets"), fm.at("offsets"), n, dim)
    elif fm.has("circle"):
        radius = number(fm.raw("circle"), fm.at("circle"), minimum=0, maximum=MAX_LENGTH)
        angle = 2.0 * math.pi * np.arange(n) / n
        offsets[:, 0], offsets[:, 1] = radius * np.cos(angle), radius * np.sin(angle)
    if fm.has("groups"):
        groups = fm.raw("groups")
        gpath = fm.at("groups")
        if not isinstance(groups, dict):
            raise SceneError(f"{gpath}: expected a mapping of group name to offset, "
                             f"got {describe(groups)}")
        for name, value in groups.items():
            if name not in sizes:
                raise SceneError(f"{gpath}.{name}: no such group (groups: {', '.join(sizes)})")
            start, size = sizes[name]
            offsets[start:start + size] += vector(value, f"{gpath}.{name}", dim)
    if not np.all(np.isfinite(offsets)) or np.max(np.abs(offsets), initial=0.0) > MAX_LENGTH:
        raise SceneError(f"{path}: offsets must be finite and below {MAX_LENGTH:g} in size")
    return offsets


def closest_pair(points: np.ndarray) -> tuple[float, int, int]:
    """(distance, i, j) of the two closest rows of ``points`` (inf, -1, -1 for fewer than 2)."""
    if len(points) < 2:
        return math.inf, -1, -1
    from scipy.spatial import cKDTree

    dist, idx = cKDTree(points).query(points, k=2)
    i = int(np.argmin(dist[:, 1]))
    return float(dist[i, 1]), i, int(idx[i, 1])


def check_separation(offsets: np.ndarray, radius: float, path: str = "formation") -> None:
    """Refuse a formation whose places are closer than 2 r (robots of radius r would collide in
    it, and a safety filter would hold them apart short of it forever)."""
    dist, i, j = closest_pair(offsets)
    if dist < 2.0 * radius:
        raise SceneError(f"{path}: agents {min(i, j)} and {max(i, j)} are {dist:.3g} apart in "
                         f"the formation, closer than 2 x safety.radius = {2.0 * radius:.3g}")


def positions(x: np.ndarray, offsets: np.ndarray | None, origin: np.ndarray,
              agents: slice | np.ndarray | range) -> np.ndarray:
    """World positions of the rows ``x`` (formation coordinates relative to ``origin``) of the
    ``agents`` (their global indices)."""
    out = np.asarray(x) + origin
    if offsets is None:
        return out
    idx = np.arange(len(offsets))[agents] if not isinstance(agents, np.ndarray) else agents
    return out + offsets[idx]
