"""What people read: progress lines, tables, command-line number types, and the one-line errors
that name the option behind them (no numerics here)."""

from __future__ import annotations

import argparse
import math
import os
import sys
import warnings
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from typing import TYPE_CHECKING, Any, TextIO

from .core.errors import ParameterError, PolymatchError, SceneError, StabilityError
from .core.scenes.checks import did_you_mean
from .core.scenes.limits import MIN_RELATIVE_TOLERANCE, Limits, parse_size
from .core.scenes.scene import INTEGRATOR_NAMES, Scene, load_scene

if TYPE_CHECKING:
    from .core.metrics import EnsembleMetrics
    from .core.scenes.scene import Scene


def positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (value > 0 and math.isfinite(value)):
        raise argparse.ArgumentTypeError(f"must be a positive finite number, got {text}")
    return value


def add_number_options(parser: argparse.ArgumentParser | argparse._ArgumentGroup,
                       table: Iterable[tuple[str, Callable[[str], Any], Any, str]]) -> None:
    """One ``--flag`` a row of ``table``: (flag, type, default, help)."""
    for flag, kind, default, text in table:
        parser.add_argument(flag, type=kind, default=default, help=text)


def tolerance_arg(text: str) -> float:
    """A relative tolerance in [MIN_RELATIVE_TOLERANCE, 1), as the scene's integrator.tolerance."""
    value = positive_float(text)
    if not value < 1:
        raise argparse.ArgumentTypeError(f"must be in (0, 1), got {text}")
    if value < MIN_RELATIVE_TOLERANCE:
        raise argparse.ArgumentTypeError(f"{text} is below {MIN_RELATIVE_TOLERANCE:g}, which "
                                         f"double precision cannot attain")
    return value


def memory_size(text: str) -> int:
    """--memory-limit: 512M, 8G, 1.5GiB or bytes."""
    try:
        return parse_size(text)
    except ParameterError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def writable_output(path: str | os.PathLike[str], suffix: str) -> str:
    """The file an output option will write (``suffix`` appended when missing), checked now.

    ``np.savez`` and matplotlib append their suffix to a bare name, so the path returned is
    the one actually written.  Raises ParameterError (exit 2) when its directory does not
    exist or is not writable, or the path is a directory, so a long run never ends in a
    failed write.
    """
    out = os.fspath(path)
    if not out or out.endswith(os.sep):
        raise ParameterError(f"{out!r}: expected a file name ending in {suffix}")
    if os.path.splitext(out)[1].lower() != suffix:
        out += suffix
    folder = os.path.dirname(os.path.abspath(out))
    if not os.path.isdir(folder):
        raise ParameterError(f"{out}: the directory {folder} does not exist")
    if os.path.isdir(out):
        raise ParameterError(f"{out}: is a directory")
    target = out if os.path.exists(out) else folder
    if not os.access(target, os.W_OK):
        raise ParameterError(f"{out}: not writable (permission denied on {target})")
    return out


def format_table(rows: Sequence[Sequence[Any]], header: Sequence[Any]) -> str:
    widths = [max(len(str(r[i])) for r in [*rows, header]) for i in range(len(header))]
    line = "  ".join(h.ljust(w) for h, w in zip(header, widths))
    out = [line, "  ".join("-" * w for w in widths)]
    out += ["  ".join(str(c).ljust(w) for c, w in zip(r, widths)) for r in rows]
    return "\n".join(out)


class Progress:
    """One updating line on a terminal, a line every few seconds otherwise."""

    def __init__(self, t_end: float, quiet: bool = False, stream: TextIO | None = None) -> None:
        import time  # noqa: PLC0415
        # sys.stderr as it is now, not as it was when this module was first imported
        stream = sys.stderr if stream is None else stream
        self.t_end, self.quiet, self.stream = t_end, quiet, stream
        self.tty = stream.isatty()
        self._time = time.monotonic
        self.start = self._time()
        self.last = -1e9

    def __call__(self, t: float, diameter: float, extra: str = "") -> None:
        if self.quiet:
            return
        now = self._time()
        if not self.tty and now - self.last < 2.0 and t < self.t_end:
            return
        if not self.tty and t >= self.t_end and getattr(self, "_ended", False):
            return
        self._ended = t >= self.t_end
        self.last = now
        pct = 100.0 * t / self.t_end if self.t_end else 100.0
        text = f"t = {t:8.3f} / {self.t_end:g} ({pct:5.1f}%)  diameter = {diameter:.3e}{extra}"
        if self.tty:
            self.stream.write("\r" + text + " " * 4)
            self.stream.flush()
        else:
            self.stream.write(text + "\n")

    def done(self) -> None:
        if self.tty and not self.quiet:
            self.stream.write("\n")


def summary_rows(scene: Scene, metrics: EnsembleMetrics) -> list[list[Any]]:
    rows = []
    for g, m in zip(scene.model.groups, metrics.groups):
        rows.append([g.name, g.size, f"{m.centroid_diameter:.3e}", f"{m.rotation_diameter:.3e}",
                     f"{m.matching_diameter:.3e}", f"{m.energy:.3e}", f"{m.orthogonality:.1e}"])
    return rows


SUMMARY_HEADER = ["group", "N", "centroid diam", "rotation diam", "matching diam", "energy",
                  "orth. defect"]


def check_integrator_option(name: str | None) -> None:
    """``--integrator NAME``: one of the known names, or an error that names the option."""
    if name is not None and name not in INTEGRATOR_NAMES:
        raise ParameterError(f"--integrator: unknown integrator {name!r}; known: "
                             f"{', '.join(INTEGRATOR_NAMES)}"
                             f"{did_you_mean(name, INTEGRATOR_NAMES)}")


def load_scene_options(name: str, t_end: float | None, limits: Limits | None = None) -> Scene:
    """The scene with ``--t-end`` applied; a refusal that only ``--t-end`` causes (a limit of
    samples or steps it exceeds) names the option and its value."""
    try:
        return load_scene(name, {"time.t_end": t_end}, limits=limits)
    except SceneError as exc:
        if t_end is None:
            raise
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                load_scene(name, limits=limits)
        except PolymatchError:
            raise exc from None                 # the scene's own problem, as the scene says
        raise ParameterError(f"--t-end {t_end:g}: {exc}") from None


@contextmanager
def naming_dt_option(dt: float | None) -> Iterator[None]:
    """A stability refusal of the step ``--dt`` gave names ``--dt``."""
    try:
        yield
    except StabilityError as exc:
        if dt is None or exc.dt != dt:
            raise
        raise StabilityError(f"--dt: {exc}", method=exc.method, dt=exc.dt, limit=exc.limit,
                             cause=exc.cause) from None
