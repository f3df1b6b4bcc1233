"""The one main of every ROS process polymatch starts: agent, monitor, echo.

``ros_main(factory)`` initialises rclpy with the process's arguments (so ``--ros-args``
remaps and parameters apply), builds the application, runs it, turns a
``PolymatchError`` into one ``<label>: error: ...`` line and its exit code, lets the
application print its final lines, and bounds the DDS teardown (``teardown_watchdog``).
"""

from __future__ import annotations

import gc
import signal
import sys
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, NoReturn

from ...core.errors import PolymatchError
from .teardown import end_process, teardown_watchdog

if TYPE_CHECKING:
    from rclpy.executors import Executor
    from rclpy.node import Node

    from ..wire import RunRecord


class NodeApp:
    """What ``ros_main`` runs for an agent or the monitor: ``self.node`` spun by
    ``self.executor``; its final lines are its run record (``final_record``), if any."""

    node: Node
    executor: Executor

    def final_record(self) -> RunRecord | None:
        """The RunRecord to print when the process ends, or None."""
        return None

    def report(self) -> None:
        """The final lines: one for people, then the run record (JSON) for programs."""
        rec = self.final_record()
        if rec is not None:
            print(rec.describe(), flush=True)
            print(rec.to_json(), flush=True)

    def destroy(self) -> None:
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()


def ros_main(
    factory: Callable[[list[str]], Any],
    label: str,
    argv: list[str] | None = None,
    interrupted_exit: int = 130,
) -> NoReturn:
    """Run ``factory(argv).run()`` and end the process with its exit code (``end_process``:
    after the bounded teardown, nothing of the interpreter's own finalization runs).

    The application may define ``report()`` (final lines, printed also after an
    interruption) and ``destroy()``.  ``interrupted_exit`` is the exit code of a Ctrl-C, also
    of one that lands while the application is still being built.
    """
    import rclpy
    from rclpy.executors import ExternalShutdownException

    argv = sys.argv if argv is None else argv
    rclpy.init(args=argv)
    app = None
    code = 0
    try:
        app = factory(argv)
        code = app.run()
    except PolymatchError as exc:
        print(f"{label}: error: {exc}", file=sys.stderr, flush=True)
        code = exc.exit_code
    except (KeyboardInterrupt, ExternalShutdownException):
        code = interrupted_exit
    finally:
        # a second Ctrl-C must not cut the report or the teardown short: ``timeout`` passes a
        # SIGINT on to its child and to its process group, so the child gets it twice, and one
        # landing in the middle of destroying the nodes once ended the monitor with a traceback,
        # and once by SIGSEGV (rclpy's own handler woke an executor being torn down).  The
        # teardown stays bounded by its watchdog.
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        if app is not None and hasattr(app, "report"):
            app.report()
        sys.stdout.flush()
        with teardown_watchdog(exit_code=code):
            if app is not None and hasattr(app, "destroy"):
                app.destroy()
            if rclpy.ok():
                rclpy.shutdown()
            # every node the process made, destroyed or not, ends here, and with its last node
            # the DDS participant and its files in /dev/shm: a destroyed LifecycleNode keeps its
            # rcl node until its state machine is collected, and a start refused while the
            # application was built leaves its nodes only to the collector (its exception held
            # them); the process then ends without the interpreter's finalization
            app = None
            gc.collect()
    end_process(code)
