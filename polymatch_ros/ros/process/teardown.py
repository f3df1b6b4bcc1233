"""Bounded teardown of a ROS process: Fast DDS 2.14 can spin for ever in ``rmw_destroy_node``.

``teardown_watchdog`` bounds the teardown with two watchdogs that need no GIL; ``end_process``
skips the interpreter's finalization; ``hung_in_teardown`` tells the supervisor that a child
ended by the watchdog had finished its work.
"""

from __future__ import annotations

import contextlib
import faulthandler
import os
import sys
from collections.abc import Iterator, Sequence
from typing import NoReturn

from .exit_timer import native_exit_timer

TEARDOWN_SECONDS = 10.0
TEARDOWN_MARK = "Timeout ("  # the first line faulthandler writes when the watchdog fires
EXIT_GRACE = 0.5  # between the stack dump and the hard exit


@contextlib.contextmanager
def teardown_watchdog(
    seconds: float = TEARDOWN_SECONDS, exit_code: int | None = 1
) -> Iterator[None]:
    """Bound the DDS teardown inside the block: past ``seconds``, end the process with
    ``exit_code`` (the code the process had decided on before its teardown).

    With Fast DDS 2.14 the last node's teardown can, rarely, spin forever at 100% CPU
    in ``DomainParticipant::set_listener`` (inside ``rmw_destroy_node``), holding the GIL and
    deaf to SIGINT/SIGTERM, so no Python thread or signal handler can run.  Two watchdogs
    that need no GIL end it: faulthandler's C thread writes ``Timeout (...)!`` and the
    Python stack to stderr; ``EXIT_GRACE`` later a POSIX timer calls ``_exit(exit_code)``
    (``native_exit_timer``), so a run that succeeded still exits 0.  Where no such timer
    can be made, faulthandler ends the process itself, with code 1.
    Enter it after the work is done and reported, around the teardown only.
    """
    timer = native_exit_timer(seconds + EXIT_GRACE, exit_code or 0)
    faulthandler.dump_traceback_later(seconds, exit=timer is None)
    try:
        yield
    finally:
        faulthandler.cancel_dump_traceback_later()
        if timer is not None:
            timer.cancel()


def hung_in_teardown(code: int | None, lines: Sequence[str]) -> bool:
    """True when a child printed its final run record, then was ended by the teardown watchdog:
    with its own exit code (the native timer), or with faulthandler's 1 where there is none."""
    from ..wire import run_records

    return (
        code is not None
        and any(line.startswith(TEARDOWN_MARK) for line in lines)
        and any(rec.finished for rec in run_records(lines))
    )


def end_process(code: int) -> NoReturn:
    """End this process now with ``code``, its output flushed.

    Call it after the bounded teardown, at the very end of a ROS process.  It skips the
    interpreter's finalization (leftover rclpy handles, Fast DDS's C++ static destructors and
    thread joins): a process that had printed its final run record and torn down under the
    watchdog was seen to hang there for minutes (twice: a lockstep agent in the tests, one in
    CI), where no watchdog reaches.
    """
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    os._exit(code)
