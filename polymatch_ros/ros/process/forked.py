"""Node processes forked from a server that imported them once.

Each node process imports Python, numpy, rclpy, its messages and the package before it does
anything; a run of many processes pays that again in every one of them.  The runner instead
starts its node processes from a fork server (Python's ``multiprocessing`` "forkserver", which
forks a child per request), so each child starts with the imports done.  Where the runner is
still single-threaded when its run begins (``fork_server``), the server is the runner's own
fork, made after the runner imported ``PRELOAD``: no second interpreter imports them again
(``_fork_server_from_here``).  Otherwise ``multiprocessing`` starts it as it does by default, a
fresh interpreter that imports ``PRELOAD``.  Nothing of ROS is initialised in the server: every
child calls ``rclpy.init`` itself, with the environment it was given, and makes its own DDS
participant, as a process started by ``exec`` would.

A child is otherwise the process ``python -m MODULE ARGS`` would be: ``sys.argv``, the
environment and ``__main__``-style exit code, its output on a pipe of the runner's, its own
process group and SIGTERM when the runner goes (``child_setup``: the server's death is its
parent's, and the server ends with the runner).  ``ForkedProcess`` gives the runner the part
of ``subprocess.Popen``'s interface it uses; ``forkable`` says which command lines qualify.
"""

from __future__ import annotations

import contextlib
import gc
import importlib
import multiprocessing
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator, Mapping, Sequence
from multiprocessing.connection import Connection
from typing import IO, NoReturn

#: the modules a forked child may run (``python -m`` with one of them); the server imports them
NODE_MODULES = (
    "polymatch_ros.ros.nodes.agent",
    "polymatch_ros.ros.nodes.monitor",
    "polymatch_ros.ros.nodes.robot",
    "polymatch_ros.ros.nodes.recorder",
)
#: what the server imports before it forks: the node modules and what they import only once
#: running (rclpy, the messages, the type support loader)
PRELOAD = (
    *NODE_MODULES,
    "rclpy",
    "rclpy.executors",
    "rclpy.lifecycle",
    "rosidl_generator_py",
    "geometry_msgs.msg",
    "nav_msgs.msg",
    "std_msgs.msg",
    "std_srvs.srv",
    "diagnostic_msgs.msg",
    "rosgraph_msgs.msg",
    "polymatch_interfaces.msg",
    "polymatch_interfaces.action",
    # what a node imports once it runs: its role's classes, the services' event messages
    "polymatch_ros.ros.agents.managed",
    "polymatch_ros.ros.agents.lockstep",
    "polymatch_ros.ros.agents.realtime",
    "polymatch_ros.ros.agents.bridge",
    "polymatch_ros.ros.agents.hosted",
    "rclpy.serialization",
    "service_msgs.msg",
    "type_description_interfaces.msg",
)
#: the message packages whose C type support every node loads when it makes its publishers,
#: subscriptions and services (``rosidl_generator_py.import_type_support``)
TYPE_SUPPORT_PACKAGES = (
    "builtin_interfaces",
    "diagnostic_msgs",
    "geometry_msgs",
    "lifecycle_msgs",
    "polymatch_interfaces",
    "rcl_interfaces",
    "service_msgs",
    "std_msgs",
    "std_srvs",
    "type_description_interfaces",
)


def preload() -> None:
    """Import ``PRELOAD`` and the type support of ``TYPE_SUPPORT_PACKAGES`` here."""
    for module in PRELOAD:
        importlib.import_module(module)
    from rosidl_generator_py import import_type_support  # type: ignore[import-untyped]

    for package in TYPE_SUPPORT_PACKAGES:
        import_type_support(package)


def child_setup() -> None:
    """In a node process, before it runs: a process group of its own, and SIGTERM when its
    parent dies (Linux): nothing outlives the runner.

    Its own group keeps a terminal's Ctrl-C (sent to the foreground group) for the runner, which
    stops the children in order.  Not a session of its own: Linux gives each session its own
    scheduling group (``/proc/sys/kernel/sched_autogroup_enabled``), and lockstep processes in
    separate groups waited about twice as long for each other's messages
    (``polymatch bench distributed``, deployed against agents, is the figure that showed it).
    """
    os.setpgid(0, 0)
    try:
        import ctypes

        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


def forkable(argv: Sequence[str]) -> str | None:
    """The node module of ``[sys.executable, "-m", MODULE, ...]`` if MODULE is one the server
    imports (``NODE_MODULES``), else None (that command line is started by ``exec``)."""
    if len(argv) >= 3 and argv[0] == sys.executable and argv[1] == "-m":
        return argv[2] if argv[2] in NODE_MODULES else None
    return None


_context: multiprocessing.context.ForkServerContext | None = None


def _server() -> multiprocessing.context.ForkServerContext:
    """The fork server's context; the server itself starts with the first child."""
    global _context
    if _context is None:
        context = multiprocessing.get_context("forkserver")
        context.set_forkserver_preload(list(PRELOAD))
        _context = context
    return _context


def _run_node(module: str, args: list[str], env: dict[str, str], out: Connection) -> None:
    """The forked child: its output to the runner's pipe, its environment, then the node's
    ``main`` as ``python -m module *args`` would run it."""
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    os.dup2(out.fileno(), 1)
    os.dup2(out.fileno(), 2)
    out.close()
    null = os.open(os.devnull, os.O_RDONLY)  # no terminal's input, as exec's stdin=DEVNULL
    os.dup2(null, 0)
    os.close(null)
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(AttributeError, ValueError):
            stream.reconfigure(line_buffering=True)  # type: ignore[union-attr]
    os.environ.clear()
    os.environ.update(env)
    child_setup()
    show_command_line([sys.executable, "-m", module, *args])
    node = importlib.import_module(module)
    sys.argv = [node.__file__ or module, *args]
    sys.exit(node.main())


def show_command_line(argv: Sequence[str]) -> bool:
    """Show ``argv`` as this process's command line (``/proc/PID/cmdline``, ``ps``): written
    over the server's own in the process's memory, whole arguments as far as they fit, the
    rest dropped.  False where the memory could not be found or written."""
    try:
        with open("/proc/self/stat", "rb") as fh:
            fields = fh.read().rsplit(b")", 1)[1].split()
        arg_start, arg_end = int(fields[45]), int(fields[46])  # stat fields 48 and 49
    except (OSError, IndexError, ValueError):
        return False
    room = arg_end - arg_start
    text = b""
    for arg in argv:
        piece = arg.encode() + b"\0"
        if len(text) + len(piece) > room:
            break
        text += piece
    if room <= 0 or not text:
        return False
    import ctypes

    ctypes.memmove(arg_start, text.ljust(room, b"\0"), room)
    return True


class ForkedProcess:
    """A node process forked from the server, with the part of ``subprocess.Popen``'s interface
    the runner uses: ``pid``, ``stdout`` (text lines), ``poll``, ``wait``, ``returncode``."""

    pid: int
    stdout: IO[str]
    returncode: int | None

    def __init__(self, argv: Sequence[str], env: Mapping[str, str] | None) -> None:
        module = forkable(argv)
        if module is None:
            raise ValueError(f"not a node module command line: {list(argv)[:3]}")
        read_end, write_end = os.pipe()
        out = Connection(write_end, readable=False)
        try:
            self._process = _server().Process(
                target=_run_node,
                args=(module, list(argv[3:]), dict(os.environ if env is None else env), out),
                name=module.rsplit(".", 1)[-1],
                daemon=True,  # an interpreter that exits with it still running ends it first
            )
            self._process.start()
        except BaseException:
            os.close(read_end)
            raise
        finally:
            out.close()  # the child has its own copy
        assert self._process.pid is not None  # started
        self.pid = self._process.pid
        self.stdout = open(read_end, encoding="utf-8", errors="replace")  # noqa: SIM115
        self.returncode = None

    def poll(self) -> int | None:
        if self.returncode is None:
            self.returncode = self._process.exitcode
        return self.returncode

    def wait(self, timeout: float | None = None) -> int:
        if self.poll() is None:
            self._process.join(timeout)
        code = self.poll()
        if code is None:
            raise subprocess.TimeoutExpired(str(self._process.name), timeout or 0.0)
        return code


_unavailable: str | None = None  # why the fork server could not be used, once it could not


@contextlib.contextmanager
def fork_server(directory: str, seconds: float = 5.0, also: Sequence[str] = ()) -> Iterator[None]:
    """The fork server of one run, started now where it can be this process's fork
    (``_fork_server_from_here``, with the modules ``also`` preloaded too: what several of the
    run's children import once running); its socket (and ``multiprocessing``'s other files) in
    the run's own ``directory``; once the block ends, the server and ``multiprocessing``'s
    resource tracker ended, each by its PID (asked, then SIGKILL after ``seconds``).

    A runner ends by ``os._exit``, skipping the interpreter's exit, where ``multiprocessing``
    would remove its temporary folder; and a server left to notice its runner's end would
    outlive it for a moment.  The caller removes ``directory`` afterwards.
    """
    config = multiprocessing.current_process()._config  # type: ignore[attr-defined]
    config["tempdir"] = directory  # ``multiprocessing.util.get_temp_dir`` takes it from here
    try:
        _fork_server_from_here(also)
        yield
    finally:
        from multiprocessing import forkserver, resource_tracker

        server = forkserver._forkserver  # type: ignore[attr-defined]
        _end_helper(server, "_forkserver_pid", "_forkserver_alive_fd", seconds)
        server._forkserver_address = None  # type: ignore[attr-defined]
        _end_helper(resource_tracker._resource_tracker, "_pid", "_fd", seconds)
        config.pop("tempdir", None)


def _fork_server_from_here(also: Sequence[str] = ()) -> bool:
    """Start the fork server as a fork of this process, once this process has imported what
    the server preloads (``preload``) and the modules ``also``; False, leaving the start to
    ``multiprocessing`` (a fresh interpreter, with the first child), where this process runs
    other threads (a fork copies only the calling thread, and a lock another one held stays
    held in the copy), already has a server, or could not make the server's socket.

    The server is ``multiprocessing``'s own loop (``forkserver.main``) with nothing left to
    import; this process then holds its socket's address, PID and "alive" pipe, as
    ``multiprocessing`` would after starting one.  The objects alive at the fork are frozen for
    the collector (``gc.freeze``) in the server and so in every child: a child's collections
    pass over none of them, and its pages of them stay shared, not copied on write.
    """
    global _unavailable
    from multiprocessing import connection, forkserver

    server = forkserver._forkserver  # type: ignore[attr-defined]
    if threading.active_count() > 1 or _unavailable is not None or vars(server).get(
            "_forkserver_pid"):
        return False
    preload()
    for module in also:
        importlib.import_module(module)
    listener = socket.socket(socket.AF_UNIX)
    try:
        address = connection.arbitrary_address("AF_UNIX")  # type: ignore[attr-defined]
        listener.bind(address)
        os.chmod(address, 0o600)
        listener.listen()
    except OSError as exc:
        listener.close()
        _unavailable = str(exc) or type(exc).__name__
        return False
    alive_r, alive_w = os.pipe()
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()  # not written again by the server's children
    gc.freeze()
    pid = os.fork()
    if pid == 0:
        _serve(listener.fileno(), alive_r)
    gc.unfreeze()
    listener.close()
    os.close(alive_r)
    vars(server).update(_forkserver_address=address, _forkserver_alive_fd=alive_w,
                        _forkserver_pid=pid)
    return True


def _serve(listener_fd: int, alive_r: int) -> NoReturn:
    """The forked server: every file this process had open closed but its standard streams,
    its socket and the read end of its "alive" pipe (a lock or pipe end of the runner's is
    not held by the server or its children), then ``multiprocessing``'s server loop, which
    ends once every holder of the pipe's write end has closed it."""
    code = 0
    try:
        _fresh_signal_handling()
        _fresh_standard_streams()
        keep = {0, 1, 2, listener_fd, alive_r}
        for name in os.listdir("/proc/self/fd"):
            if int(name) not in keep:
                with contextlib.suppress(OSError):
                    os.close(int(name))
        from multiprocessing import forkserver

        forkserver.main(listener_fd, alive_r, [])
    except SystemExit:
        pass
    except BaseException:  # noqa: BLE001 -- the server's end is its runner's to see
        code = 1
    finally:
        os._exit(code)


def _fresh_signal_handling() -> None:
    """Signals handled as in a fresh interpreter: no wakeup file (the runner's would be written
    to by the server's signals), and every handler this process set in Python back to the
    default (Ctrl-C's ``KeyboardInterrupt`` for SIGINT)."""
    signal.set_wakeup_fd(-1)
    for number in signal.valid_signals():
        handler = signal.getsignal(number)
        if callable(handler) and handler is not signal.default_int_handler:
            signal.signal(number, signal.default_int_handler if number == signal.SIGINT
                          else signal.SIG_DFL)


#: the streams this process had as ``sys.stdout`` and ``sys.stderr`` when it became a server,
#: kept from being deallocated (which would close their files: perhaps numbers reused by then)
_inherited_streams: list[object] = []


def _fresh_standard_streams() -> None:
    """``sys.stdout`` and ``sys.stderr`` on files 1 and 2, as in a fresh interpreter: the
    runner's may write elsewhere (a test's capture), and a child writes what it prints through
    them once its output pipe is on 1 and 2 (``_run_node``)."""
    _inherited_streams.extend((sys.stdout, sys.stderr))
    sys.stdout = open(1, "w", closefd=False)  # noqa: SIM115
    sys.stderr = open(2, "w", errors="backslashreplace", buffering=1, closefd=False)  # noqa: SIM115


def _end_helper(helper: object, pid_name: str, fd_name: str, seconds: float) -> None:
    """End one of ``multiprocessing``'s helper processes: close the pipe whose end tells it to
    stop, wait ``seconds`` at most, then SIGKILL it; forget it, so that a later start makes a
    new one."""
    pid, fd = getattr(helper, pid_name, None), getattr(helper, fd_name, None)
    setattr(helper, pid_name, None)
    setattr(helper, fd_name, None)
    if fd is not None:
        with contextlib.suppress(OSError):
            os.close(fd)
    if pid is None:
        return
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        with contextlib.suppress(ChildProcessError):
            if os.waitpid(pid, os.WNOHANG)[0] == 0:
                time.sleep(0.02)
                continue
        return
    with contextlib.suppress(ProcessLookupError):
        os.kill(pid, signal.SIGKILL)
    with contextlib.suppress(ChildProcessError):
        os.waitpid(pid, 0)


def start(argv: Sequence[str], env: Mapping[str, str] | None) -> ForkedProcess | None:
    """``argv`` forked from the server if it is a node module's command line (``forkable``),
    else None (the caller starts it by ``exec``); None too, from then on, where the server
    cannot be started or reached (no room for its socket, a server that died)."""
    global _unavailable
    if forkable(argv) is None or _unavailable is not None:
        return None
    try:
        return ForkedProcess(argv, env)
    except (OSError, EOFError) as exc:
        _unavailable = str(exc) or type(exc).__name__
        return None
