"""A scene's full model on one flat vector, for a general-purpose solver (scipy's ``solve_ivp``).

Per group, in this order: centroids xbar (N, d), rotation matrices O (N, d, d) and, for the
second-order model, xbar' (N, d) and the spatial angular velocities W (N, d, d) skew:

    (A-2)  xbar_i' = F_i / gamma,            O_i' = W_i O_i,  W_i = the Lohe rate of (A-2)
    (A-1)  xbar_i'' = (F_i - gamma xbar_i') / m,   O_i' = W_i O_i,
           W_i' = (kappa/(2N) (S O_i^T - O_i S^T) - gamma W_i) / m

with F_i the centroid force (consensus, on a graph the in-neighbours', F-2 between groups) and
S the (F-1 weighted) mean field.  The right-hand side is the package's own (``System.couple``,
``System.rates``) on the matrix representation with the centroids integrated, so the
flattened system is the scene's model, every coupling included; what differs from our
integrators is the solver: nothing keeps O_i in SO(d) (Lemma 2.1 is a property of the ODE,
a general-purpose solver keeps it to its tolerance) and the centroids are integrated
rather than advanced by the exact flow of Proposition 2.1.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np

from ..model import GroupState, State, System
from ..so import group_for

if TYPE_CHECKING:
    from ..scenes.scene import Scene

__all__ = ["FlatModel"]


class FlatModel:
    """Packing, unpacking and the right-hand side of a scene on one flat vector."""

    def __init__(self, scene: Scene) -> None:
        model = scene.model
        self.group = group_for(model.dim, "matrix")
        self.model = replace(model, rotations=self.group, centroids="integrated")
        self.system = System(self.model)
        self.order, self.dim = model.order, model.dim
        self.evaluations = 0
        d = self.dim
        names = ("x", "rot") if self.order == 1 else ("x", "rot", "v", "w")
        shapes = {"x": (d,), "rot": (d, d), "v": (d,), "w": (d, d)}
        self.layout: list[tuple[int, str, tuple[int, ...], slice]] = []
        pos = 0
        for gi, g in enumerate(model.groups):
            for name in names:
                shape = (g.size,) + shapes[name]
                size = int(np.prod(shape))
                self.layout.append((gi, name, shape, slice(pos, pos + size)))
                pos += size
        self.size = pos

    def initial(self, scene: Scene) -> np.ndarray:
        """y0: the scene's initial state (centroids relative to its origin, as the core holds
        them)."""
        rep = scene.model.rotations
        y = np.empty(self.size)
        for gi, name, _shape, sl in self.layout:
            gs = scene.initial.groups[gi]
            assert gs is not None  # a scene's initial state has every group
            value: Any = {"x": gs.x, "v": gs.v}.get(name)
            if name == "rot":
                value = rep.to_matrices(gs.rot)
            elif name == "w":
                assert gs.w is not None  # a second-order scene has angular velocities
                value = rep.algebra_to_skew(gs.w)
            y[sl] = np.ravel(value)
        return y

    def unpack(self, y: np.ndarray) -> list[dict[str, np.ndarray]]:
        """Per group: {"x", "rot" (matrices), ["v", "w" (skew)]} viewed from one state y."""
        out: list[dict[str, np.ndarray]] = [{} for _ in self.model.groups]
        for gi, name, shape, sl in self.layout:
            out[gi][name] = y[sl].reshape(shape)
        return out

    def states(self, y: np.ndarray) -> tuple[GroupState, ...]:
        """The group states of one flat vector, in the matrix representation."""
        grp = self.group
        return tuple(GroupState(p["x"], grp.from_matrices(p["rot"]), p.get("v"),
                                None if "w" not in p else grp.algebra_from_skew(p["w"]))
                     for p in self.unpack(y))

    def rhs(self, t: float, y: np.ndarray) -> np.ndarray:
        """dy/dt of (A-1)/(A-2) (with F-1 and F-2) at the flat state y."""
        self.evaluations += 1
        groups = self.states(y)
        system, grp = self.system, self.group
        coupling = system.couple(groups, first_stage=True)
        rates = system.rates(State(t, groups), coupling)
        out = np.empty_like(y)
        parts = self.unpack(y)
        for gi, name, _shape, sl in self.layout:
            rate = rates[gi]
            assert rate is not None  # every group has its rows
            k_rot, k_x, k_v, k_w = rate
            if name == "x":
                value = k_x
            elif name == "v":
                value = k_v
            elif name == "w":
                value = grp.algebra_to_skew(k_w)
            else:
                value = grp.algebra_to_skew(k_rot) @ parts[gi]["rot"]
            out[sl] = np.ravel(value)
        return out
