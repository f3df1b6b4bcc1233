"""Fixed-step Munthe-Kaas methods whose stage slopes are the rows of one matrix.

``ChartRK`` is ``rk.RKMK`` (stages O = psi(Theta) O_n, slopes dpsi^{-1}_Theta(W), Lemma 2.1:
rotations stay in SO(d) with no projection) with the stage sums taken in the flat increment
coordinates of the adaptive method (``adaptive_chart.Chart``): the slopes k_1..k_s are the
rows of one (s, n) matrix and a stage's increment h sum_j a_ij k_j is one matrix-vector
product, not s array updates.  Same tableau, same stages, same exchanges per step as the
RKMK of that tableau (to round-off); worth it for many stages over many rows.

``RKMK8`` is DOP853's 8th-order tableau (scipy's coefficients, the 12 stages of its
8th-order solution; ``adaptive.AdaptiveLie`` adds error control and dense output) on a
fixed grid.  It is for batches of ensembles (``core.sweep``): at a step as long as the
sample interval it is more accurate than rkmk4 at a tenth of that step, with 12 evaluations
per interval against rkmk4's 40 (``polymatch bench sweep``).  Not in the registry
``integrators.METHODS``: ``core.sweep.BATCH_METHODS`` names it.
"""

from collections.abc import Sequence

import numpy as np

from ..model import Coupling, State, System
from ..stepping.adaptive_chart import Chart
from ..stepping.rk import RKMK
from ..stepping.solver import Stepper


class ChartRK(RKMK):
    """RKMK of an explicit tableau with its stage sums as matrix products (module doc)."""

    def __init__(self, name: str, a: Sequence, b: Sequence, order: int, summary: str) -> None:
        super().__init__(name, a, b, order, summary)
        tableau = np.asarray(self.a)
        self.rows = [np.ascontiguousarray(tableau[s, :s]) for s in range(1, len(self.b))]
        self.weights = np.asarray(self.b)

    def stages(self, system: System, y: State, h: float, coupling: Coupling,
               centroids: list | None) -> Stepper:
        """``Method.stages``: slopes in the chart centred at y, one row per stage."""
        chart = Chart(system, y)
        slopes = np.empty((len(self.b), chart.n))
        slopes[0] = chart.pack(self.slopes(system, y, coupling, None))
        for s, row in enumerate(self.rows, start=1):
            stage, thetas = chart.state((row @ slopes[:s]) * h)
            c = yield from system.evaluate(stage)
            slopes[s] = chart.pack(self.slopes(system, stage, c, thetas))
        end, _ = chart.state((self.weights @ slopes) * h)
        return end


_BUILT: dict[str, ChartRK] = {}


def __getattr__(name: str) -> ChartRK:
    """``RKMK8``, built on first use: its tableau comes from scipy.integrate, an import of
    about half a second that a ``polymatch`` command refusing its arguments never needs."""
    if name != "RKMK8":
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    if name not in _BUILT:
        from scipy.integrate import DOP853
        _BUILT[name] = ChartRK(
            "rkmk8", DOP853.A[:DOP853.n_stages, :DOP853.n_stages], DOP853.B, 8,
            "Munthe-Kaas with DOP853's 8th-order tableau on a fixed step (12 stages)")
    return _BUILT[name]
