"""Wall-clock measurement shared by the benchmark families.

Timings on a shared machine are noisy, so every figure is a set of repeats:
``best`` (least disturbed, the most reproducible number), ``median`` and
``max`` (how much the machine disturbed the run).  Benchmarks report these;
they never assert on them.
"""

import gc
import os
import platform
import statistics
import time
from dataclasses import dataclass

import numpy as np
import scipy


@dataclass(frozen=True)
class Timing:
    """Seconds per call over ``len(samples)`` repeats."""

    samples: tuple

    @property
    def best(self):
        return min(self.samples)

    @property
    def median(self):
        return statistics.median(self.samples)

    @property
    def worst(self):
        return max(self.samples)

    @property
    def repeats(self):
        return len(self.samples)

    @property
    def spread(self):
        """(max - best) / best: 0.1 means the slowest repeat took 10% longer than the best."""
        return self.worst / self.best - 1.0 if self.best > 0 else 0.0

    def scaled(self, factor):
        return Timing(tuple(s * factor for s in self.samples))


def measure(fn, repeats, setup=None, warmup=1):
    """Time ``fn(setup())`` ``repeats`` times (``setup`` untimed), after ``warmup`` untimed calls.

    The garbage collector is paused while timing, as ``timeit`` does.
    """
    return measure_interleaved([(fn, setup)], repeats, warmup)[0]


def measure_interleaved(cases, repeats, warmup=1):
    """Time several ``(fn, setup)`` cases round-robin, one repeat of each per round.

    A change of machine load during the measurement then hits every case alike,
    which keeps their ratios meaningful.  Returns one ``Timing`` per case.
    """
    for fn, setup in cases:
        for _ in range(warmup):
            fn(setup() if setup else None)
    samples = [[] for _ in cases]
    enabled = gc.isenabled()
    gc.disable()
    try:
        for _ in range(max(1, int(repeats))):
            for (fn, setup), out in zip(cases, samples):
                arg = setup() if setup else None
                t0 = time.perf_counter()
                fn(arg)
                out.append(time.perf_counter() - t0)
    finally:
        if enabled:
            gc.enable()
    return [Timing(tuple(s)) for s in samples]


def fmt_time(seconds, unit=None):
    """'2.71 ms', '350 µs', '1.24 s' (or a fixed unit: 's', 'ms', 'us')."""
    if unit is None:
        unit = "s" if seconds >= 1 else "ms" if seconds >= 1e-3 else "us"
    value = seconds * {"s": 1.0, "ms": 1e3, "us": 1e6}[unit]
    text = f"{value:.3g}" if value < 100 else f"{value:.0f}"
    return f"{text} {'µs' if unit == 'us' else unit}"


def fmt_ms(seconds):
    return f"{seconds * 1e3:.3f}" if seconds < 0.1 else f"{seconds * 1e3:.1f}"


def load_span(load):
    """'load averages (1, 5, 15 min) at the start a/b/c, at the end d/e/f, on N cores' of the
    ``os.getloadavg()`` samples ``load`` taken during a family's runs (first and last)."""
    def fmt(sample):
        return "/".join(f"{v:.1f}" for v in sample)
    return (f"load averages (1, 5, 15 min) at the start {fmt(load[0])}, at the end "
            f"{fmt(load[-1])}, on {os.cpu_count()} cores")


def machine_lines():
    """A few lines that say on what the figures were measured."""
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    try:
        load = "load average {:.2f} {:.2f} {:.2f}".format(*os.getloadavg())
    except OSError:
        load = "load average unknown"
    blas = _blas_name()
    threads = {k: os.environ[k]
               for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
               if k in os.environ}
    return [f"machine: {cpu}, {os.cpu_count()} logical cores, {load} at start",
            f"python {platform.python_version()}, numpy {np.__version__} ({blas}), "
            f"scipy {scipy.__version__}"
            + (f", {threads}" if threads else ""),
            f"date: {time.strftime('%Y-%m-%d %H:%M:%S %Z')}"]


def _blas_name():
    try:
        cfg = np.show_config(mode="dicts")
        return cfg["Build Dependencies"]["blas"]["name"]
    except Exception:   # older numpy without mode="dicts": not worth failing a benchmark over
        return "blas unknown"
