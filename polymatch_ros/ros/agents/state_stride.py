"""Which lockstep steps go out on the run's exchange: what the monitor reads, at its pace.

The monitor reports a few times a second (``report_rate``) the latest step that every agent
has reached.  Sending it every step's states made it cost a packed lockstep run a quarter to a
half of its rounds: the agents encode a message a step, and the monitor decodes them all.  So
each process sends the states of the steps that are multiples of a stride S = 2^j, the
largest that keeps S of its own steps within ``1 / exchange_rate`` wall-clock seconds, and
always its first and last step.  Every process finds its own stride, but all of them are
powers of two: the multiples of the largest are steps that every process sends, so the monitor
still completes a step every ``1 / exchange_rate`` s or so, and each step it reports is exact
(the states of every agent at that step, as the centralised run has them).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

#: the longest stride: a step at least every this many, however fast the steps
MOST_STEPS = 1 << 16


class StateStride:
    """``due(step)``: whether this process sends the states of ``step`` on the exchange.

    ``rate`` Hz (0: every step) is how often; the stride is measured on this process's pace,
    from the wall-clock time since the last step it sent: at each step it sends, and at every
    step once a period has passed without one (a pace that fell shortens the stride at once)."""

    def __init__(self, rate: float, clock: Callable[[], float] = time.monotonic) -> None:
        self.period = 0.0 if rate <= 0 else 1.0 / float(rate)
        self.stride = 1
        self.clock = clock
        self.mark: tuple[int, float] | None = None  # (step, wall time) of the last one sent

    def due(self, step: int, last: bool = False) -> bool:
        """True for the steps to send: multiples of the stride, and the ``last`` step."""
        if self.period == 0.0:
            return True
        now = self.clock()
        if self.mark is not None and step > self.mark[0]:
            elapsed = now - self.mark[1]
            # at a step it sends, or once a period has passed without one (the pace fell)
            if step % self.stride == 0 or elapsed > self.period:
                self.stride = power_of_two_within(self.period, elapsed / (step - self.mark[0]))
        if step % self.stride and not last:
            return False
        self.mark = (step, now)
        return True


def power_of_two_within(period: float, per_step: float) -> int:
    """The largest 2^j (1 .. ``MOST_STEPS``) with 2^j steps of ``per_step`` s within
    ``period`` s."""
    if per_step <= 0.0:
        return MOST_STEPS
    steps = period / per_step
    if steps < 2.0:
        return 1
    return min(MOST_STEPS, 1 << int(math.floor(math.log2(steps))))
