"""Explicit Runge-Kutta families: Munthe-Kaas on SO(d) (lie) and RK + projection (baselines).

Both combine stage slopes with one tableau; they differ only in how a rotation moves:

lie          Runge-Kutta-Munthe-Kaas: stages O_i = psi(Theta_i) O_n with Theta_i in so(d),
             k_i = dpsi^{-1}_{Theta_i}(W(O_i)).  Rotations stay in SO(d) to round-off
             (Lemma 2.1) with no projection.  psi = exp (angles in 2-D) or Cayley (d >= 3).
projection   Classical RK in the embedding R^{d x d}, then the polar factor (baselines).
"""

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from ..model import Coupling, GroupState, State, System
from ..so.base import Array
from .solver import Method, MethodInfo, Stepper, advance_active, lincomb


def rk_stability(a: npt.ArrayLike, b: npt.ArrayLike, z: npt.ArrayLike) -> np.ndarray:
    """R(z) = 1 + z b^T (I - z A)^{-1} 1 for an explicit tableau, vectorised over complex z."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    z = np.atleast_1d(np.asarray(z, dtype=complex))
    s = len(b)
    out = np.empty_like(z)
    for n, zz in enumerate(z):
        k = np.linalg.solve(np.eye(s) - zz * a, np.ones(s))
        out[n] = 1.0 + zz * (b @ k)
    return out


class ExplicitRK(Method):
    """An explicit tableau (a, b): stages y + h sum_j a_ij k_j, the step's end y + h sum_j b_j k_j.

    The combinator is shared; subclasses say how a rotation moves (``move_rotation``)
    and what a stage's rotation slope is (``slopes``).
    """

    family = ""

    def __init__(self, name: str, a: Sequence, b: Sequence, order: int, summary: str) -> None:
        self.a = [list(map(float, row)) for row in a]
        self.b = list(map(float, b))
        self.info = MethodInfo(name, order, len(b), len(b), self.family, (1, 2), summary)

    def stages(self, system: System, y: State, h: float, coupling: Coupling,
               centroids: list | None) -> Stepper:
        ks = [self.slopes(system, y, coupling, None)]
        for i in range(1, len(self.b)):
            stage, thetas = self.combine(system, y, h, self.a[i][:i], ks, final=False)
            c = yield from system.evaluate(stage)
            ks.append(self.slopes(system, stage, c, thetas))
        end, _ = self.combine(system, y, h, self.b, ks, final=True)
        return end

    def combine(self, system: System, y: State, h: float, row: Sequence[float], ks: list,
                final: bool) -> tuple[State, list]:
        """(y + h sum row_j k_j, per-group rotation increments) — a stage or the step's end."""
        model = system.model

        def combine_group(gi, gs):
            kk = [k[gi] for k in ks]
            rot, theta = self.move_rotation(system, gs.rot, h, row, [k[0] for k in kk], final)
            x, v, w = gs.x, gs.v, gs.w
            if not model.centroids_exact:
                x = lincomb(gs.x, h, row, [k[1] for k in kk])
                if model.order == 2:
                    v = lincomb(gs.v, h, row, [k[2] for k in kk])
            if model.order == 2:
                w = lincomb(gs.w, h, row, [k[3] for k in kk])
            return GroupState(x, rot, v, w), theta
        groups, thetas = advance_active(system, y.groups, combine_group)
        return State(y.t, groups), thetas

    def move_rotation(self, system: System, rot: Array, h: float, row: Sequence[float],
                      slopes: list, final: bool) -> tuple[Array, Array | None]:
        """(new rotations, increment Theta in so(d) or None) from the rotation slopes."""
        raise NotImplementedError

    def slopes(self, system: System, stage: State, coupling: Coupling,
               thetas: Sequence | None) -> list:
        """Per-group stage slopes (k_rot, k_x, k_v, k_w) in the method's coordinates."""
        raise NotImplementedError

    def spectral_radius(self, h: float, a: np.ndarray) -> float:
        lam = np.linalg.eigvals(np.atleast_2d(a))
        return float(np.max(np.abs(rk_stability(self.a, self.b, h * lam))))


class RKMK(ExplicitRK):
    """Runge-Kutta-Munthe-Kaas method of a tableau (rotations via psi = exp / Cayley)."""

    family = "lie"

    def move_rotation(self, system: System, rot: Array, h: float, row: Sequence[float],
                      slopes: list, final: bool) -> tuple[Array, Array | None]:
        theta = lincomb(None, h, row, slopes)
        return (rot if theta is None else system.group.retract(theta, rot)), theta

    def slopes(self, system: System, stage: State, coupling: Coupling,
               thetas: Sequence | None) -> list:
        return system.in_chart(system.rates(stage, coupling), thetas)


class ProjectedRK(ExplicitRK):
    """Classical explicit RK on O' = W O in R^{d x d}, polar projection at the end of each step."""

    family = "projection"

    def check_system(self, system: System) -> None:
        if system.group.name == "angle":
            raise TypeError(f"{self.name} needs the matrix representation of SO(2)")

    def move_rotation(self, system: System, rot: Array, h: float, row: Sequence[float],
                      slopes: list, final: bool) -> tuple[Array, Array | None]:
        rot = lincomb(rot, h, row, slopes)
        return (system.group.project(rot) if final else rot), None

    def slopes(self, system: System, stage: State, coupling: Coupling,
               thetas: Sequence | None) -> list:
        grp = system.group
        return [None if r is None or gs is None else (grp.tangent(r[0], gs.rot),) + tuple(r[1:])
                for r, gs in zip(system.rates(stage, coupling), stage.groups)]
