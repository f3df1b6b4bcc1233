"""The integrator registry: named fixed-step methods with order, stage count and stability.

Every method follows one contract (``solver.Method``): ``method.step(system, state, h)``
is a generator that yields each stage state whose mean field it needs, receives the
ensemble for that stage (full group arrays), and returns the new state.  The centralised
simulator answers with its own arrays; a ROS agent in lockstep publishes its rows and
answers with what its peers sent.  One stepper serves both, which is why the
distributed trajectory equals the centralised one to round-off.

Families
--------
lie          Runge-Kutta-Munthe-Kaas on SO(d), no projection (Lemma 2.1)      ``rk``
projection   classical RK in R^{d x d} + polar factor (baselines)            ``rk``
exponential  damping integrated exactly, for stiff m/gamma (A-1)             ``second_order``
splitting    Strang splitting, symplectic for gamma = 0 (Prop. 2.2)          ``second_order``
adaptive     DOP853 in psi-coordinates, centralised only                     ``adaptive``

Centroids that decouple (one group, or no inter-group potential) are advanced by
the exact flow of Proposition 2.1 inside every method (the base contract does it);
only F-2 centroids are integrated with the method's own stages.
"""

from ..errors import StabilityError
from .rk import RKMK, ExplicitRK, ProjectedRK, rk_stability
from .second_order import ExponentialLie, LieVerlet, phi_functions
from .solver import Method, MethodInfo
from .stability import check_stability, max_stable_dt, test_matrices

__all__ = ["METHODS", "ExplicitRK", "ExponentialLie", "LieVerlet", "Method", "MethodInfo",
           "ProjectedRK", "RKMK", "check_stability", "get_method", "max_stable_dt",
           "phi_functions", "rk_stability", "test_matrices"]

_RK4_A = [[0, 0, 0, 0], [0.5, 0, 0, 0], [0, 0.5, 0, 0], [0, 0, 1, 0]]
_RK4_B = [1 / 6, 1 / 3, 1 / 3, 1 / 6]

METHODS: dict[str, Method] = {
    m.name: m for m in (
        RKMK("lie_euler", [[0]], [1], 1, "Lie-Euler: O <- psi(h W(O)) O"),
        RKMK("lie_heun", [[0, 0], [1, 0]], [0.5, 0.5], 2, "Munthe-Kaas Heun (RK2)"),
        RKMK("rkmk4", _RK4_A, _RK4_B, 4, "Munthe-Kaas classical RK4 (Cayley/exp coordinates)"),
        ProjectedRK("euler_proj", [[0]], [1], 1,
                    "explicit Euler in R^{dxd} + polar projection (baseline)"),
        ProjectedRK("rk4_proj", _RK4_A, _RK4_B, 4,
                    "classical RK4 in R^{dxd} + polar projection (baseline)"),
        ExponentialLie(1),
        ExponentialLie(2),
        LieVerlet(),
    )
}


def get_method(name: str) -> Method:
    """The registered method ``name``; StabilityError naming the known ones otherwise."""
    try:
        return METHODS[name]
    except KeyError:
        known = ", ".join(sorted(METHODS) + ["adaptive"])
        raise StabilityError(f"unknown integrator {name!r}; known: {known}",
                             method=name) from None
