"""An exit that needs neither the GIL nor a signal handler: a POSIX timer whose notify
function is libc's ``_exit``.

``teardown_watchdog`` (``ros_env``) arms one around the DDS teardown, which can spin
forever holding the GIL; when it fires, a libc helper thread ends the process with the exit
code the process had already decided on.  Linux/glibc layouts; elsewhere
``native_exit_timer`` returns None and the caller falls back to faulthandler's exit.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import time


class _SigVal(ctypes.Union):
    _fields_ = [("sival_int", ctypes.c_int), ("sival_ptr", ctypes.c_void_p)]


class _SigEvent(ctypes.Structure):  # glibc's struct sigevent (64 bytes), SIGEV_THREAD member
    _fields_ = [("sigev_value", _SigVal), ("sigev_signo", ctypes.c_int),
                ("sigev_notify", ctypes.c_int), ("sigev_notify_function", ctypes.c_void_p),
                ("sigev_notify_attributes", ctypes.c_void_p), ("_pad", ctypes.c_int * 8)]


class _ITimerSpec(ctypes.Structure):
    _fields_ = [("interval_sec", ctypes.c_long), ("interval_nsec", ctypes.c_long),
                ("value_sec", ctypes.c_long), ("value_nsec", ctypes.c_long)]


class NativeExitTimer:
    """A POSIX timer (``timer_create`` with ``SIGEV_THREAD``) whose notify function is libc's
    ``_exit`` and whose value is the exit code: when it fires, a libc helper thread ends
    the process with that code, whatever the Python threads are doing."""

    SIGEV_THREAD = 2

    def __init__(self, libc: ctypes.CDLL, seconds: float, exit_code: int) -> None:
        self._libc = libc
        event = _SigEvent(sigev_notify=self.SIGEV_THREAD)
        event.sigev_value.sival_int = int(exit_code)
        event.sigev_notify_function = ctypes.cast(libc._exit, ctypes.c_void_p).value
        self._id: ctypes.c_void_p | None = ctypes.c_void_p()
        if libc.timer_create(time.CLOCK_MONOTONIC, ctypes.byref(event), ctypes.byref(self._id)):
            raise OSError(ctypes.get_errno(), "timer_create")
        whole = int(seconds)
        spec = _ITimerSpec(value_sec=whole, value_nsec=int((seconds - whole) * 1e9))
        if libc.timer_settime(self._id, 0, ctypes.byref(spec), None):
            self.cancel()
            raise OSError(ctypes.get_errno(), "timer_settime")

    def cancel(self) -> None:
        if self._id is not None:
            self._libc.timer_delete(self._id)
            self._id = None


def _load_libc() -> ctypes.CDLL | None:
    """glibc by its soname (no ``find_library``: that runs ``ldconfig`` in a subprocess, which
    a process ending with DDS threads alive must not depend on), else by search; or None."""
    try:
        return ctypes.CDLL("libc.so.6", use_errno=True)
    except OSError:
        pass
    try:
        name = ctypes.util.find_library("c")
        return ctypes.CDLL(name, use_errno=True) if name else None
    except OSError:
        return None


_LIBC = _load_libc()  # loaded with the module, before any teardown needs it


def native_exit_timer(
    seconds: float, exit_code: int, libc: ctypes.CDLL | None = _LIBC
) -> NativeExitTimer | None:
    """A ``NativeExitTimer`` armed for ``seconds``, or None where libc has no POSIX timers."""
    if libc is None:
        return None
    try:
        libc.timer_delete.argtypes = [ctypes.c_void_p]
        libc.timer_settime.argtypes = [ctypes.c_void_p, ctypes.c_int, ctypes.c_void_p,
                                       ctypes.c_void_p]
        return NativeExitTimer(libc, seconds, exit_code)
    except (OSError, AttributeError, TypeError):
        return None
