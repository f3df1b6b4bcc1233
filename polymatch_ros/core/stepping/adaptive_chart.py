"""Flat increment coordinates of the adaptive DOP853-Lie method, centred at a state.

An increment vector holds, per group with local rows, Theta in so(d) (the rotations move as
psi(Theta) O) and, when the stages integrate them, the centroid, velocity and angular-velocity
offsets.  ``Chart.state`` turns an increment into the stage state the right-hand side sees,
``Chart.pack`` the right-hand side's rates into one flat vector.
"""

from typing import Any

import numpy as np

from ..model import Coupling, GroupCoupling, GroupState, State, System
from ..so.base import Array


class Chart:
    """Flat increment coordinates centred at the state y: per group rot, [x, v,] [w]."""

    def __init__(self, system: System, y: State) -> None:
        self.system, self.y = system, y
        grp, model = system.group, system.model
        self.parts: list[tuple[int, str, tuple[int, ...], slice]] = []
        pos = 0
        is_rot: list[np.ndarray] = []
        for gi, gs in enumerate(y.groups):
            if gs is None or grp.count(gs.rot) == 0:
                continue
            fields: list[tuple[str, Any]] = [("rot", grp.algebra_zeros(grp.count(gs.rot)))]
            if not model.centroids_exact:
                fields.append(("x", gs.x))
                if model.order == 2:
                    fields.append(("v", gs.v))
            if model.order == 2:
                fields.append(("w", gs.w))
            for kind, value in fields:
                size = value.size
                self.parts.append((gi, kind, value.shape, slice(pos, pos + size)))
                is_rot.append(np.full(size, kind == "rot"))
                pos += size
        self.n = pos
        self.is_rot = np.concatenate(is_rot) if is_rot else np.zeros(0, dtype=bool)
        self.rotations_only = bool(np.all(self.is_rot))
        self.single_part = len(self.parts) == 1         # one group, rotations only
        self._centre(y)

    def _centre(self, y: State) -> None:
        self.y = y
        if self.rotations_only:                       # the increment itself: base 0, unit size
            self.base = np.zeros(self.n)
            self.base_size = np.ones(self.n)
            return
        self.base = np.zeros(self.n)                  # 0 in the rotation slots
        for gi, kind, _, sl in self.parts:
            if kind != "rot":
                self.base[sl] = np.ravel(getattr(y.groups[gi], kind))
        self.base_size = np.where(self.is_rot, 1.0, np.abs(self.base))   # rotations: unit size

    def at(self, y: State) -> "Chart":
        """The same layout centred at another state of the ensemble (the next step's chart)."""
        chart = Chart.__new__(Chart)                 # a shallow copy (copy.copy costs more)
        chart.__dict__.update(self.__dict__)
        if self.rotations_only:
            chart.y = y
        else:
            chart._centre(y)
        return chart

    def state(self, vec: np.ndarray) -> tuple[State, list[Array | None]]:
        """(State at psi(vec) . y, per-group Theta): the stage the right-hand side sees."""
        grp = self.system.group
        groups: list[Any] = list(self.y.groups)
        thetas: list[Array | None] = [None] * len(groups)
        start: Any = self.y.groups                   # every part's group has rows
        if self.single_part:                          # one group, rotations only (first order)
            gi, _, shape, _ = self.parts[0]
            gs = groups[gi]
            thetas[gi] = theta = vec.reshape(shape)
            groups[gi] = GroupState(gs.x, grp.retract(theta, gs.rot), gs.v, gs.w)
            return State(self.y.t, tuple(groups)), thetas
        for gi, kind, shape, sl in self.parts:
            piece = vec[sl].reshape(shape)
            gs = groups[gi]
            if kind == "rot":
                thetas[gi] = piece
                groups[gi] = GroupState(gs.x, grp.retract(piece, gs.rot), gs.v, gs.w)
            elif kind == "x":
                groups[gi] = GroupState(start[gi].x + piece, gs.rot, gs.v, gs.w)
            elif kind == "v":
                groups[gi] = GroupState(gs.x, gs.rot, start[gi].v + piece, gs.w)
            else:
                groups[gi] = GroupState(gs.x, gs.rot, gs.v, start[gi].w + piece)
        return State(self.y.t, tuple(groups)), thetas

    _INDEX = {"rot": 0, "x": 1, "v": 2, "w": 3}

    def pack(self, rates: list[Any]) -> np.ndarray:
        if self.single_part:                          # one group, rotations only: no copy needed
            return rates[self.parts[0][0]][0].reshape(-1)
        out = np.empty(self.n)
        for gi, kind, _shape, sl in self.parts:
            out[sl] = rates[gi][self._INDEX[kind]].reshape(-1)
        return out


class RotationRates:
    """Chart rates of a one-group, rotations-only first-order chart, without state objects.

    For such a chart (no graph: one mean field for the group) ``Chart.state``,
    ``System.couple(first_stage=False)``, ``System.rates`` and ``System.in_chart`` reduce to

        O = psi(Theta) O_n,  S = sum_k [s_k] O_k,  k = dpsi^{-1}_Theta(W(O))   (A-2), (F-1),

    and this makes exactly those calls, in that order, so its rates are bitwise the general
    path's; it only skips building a State, GroupState and Coupling for every stage.
    """

    def __init__(self, chart: Chart) -> None:
        system = chart.system
        self.gi, _, self.shape, _ = chart.parts[0]
        self.group, self.system = system.group, system
        self.scales = system.model.groups[self.gi].scales
        self.slot: list[GroupCoupling | None] = [None] * len(chart.y.groups)

    @staticmethod
    def applies(chart: Chart) -> bool:
        model = chart.system.model
        return (chart.single_part and model.order == 1 and model.centroids_exact
                and model.groups[chart.parts[0][0]].graph is None)

    def __call__(self, chart: Chart, vec: np.ndarray) -> tuple[np.ndarray, Array, Array]:
        """(flat chart rates, stage rotations, raw rate W) at the increment ``vec``."""
        grp, gi = self.group, self.gi
        theta = vec.reshape(self.shape)
        start = chart.y.groups[gi]
        assert start is not None, "the chart's group has rows"
        rot = grp.retract(theta, start.rot)
        slot = self.slot
        slot[gi] = GroupCoupling(grp.mean_field(rot, self.scales), grp.count(rot))
        rate = self.system.rotation_rate(gi, rot, Coupling(tuple(slot)))
        k = rate if grp.abelian else grp.dpsi_inv(theta, rate)
        return k.reshape(-1), rot, rate

    def stage(self, chart: Chart, rot: Array, rate: Array) -> tuple[State, list[Any]]:
        """(State, raw rates) of the stage at rotations ``rot``: what ``Chart.state`` and
        ``System.rates`` return there."""
        groups: list[Any] = list(chart.y.groups)
        raw: list[Any] = [None] * len(chart.y.groups)
        gs = groups[self.gi]
        groups[self.gi] = GroupState(gs.x, rot, gs.v, gs.w)
        raw[self.gi] = (rate, None, None, None)
        return State(chart.y.t, tuple(groups)), raw
