"""Launch-free helpers for the multi-process ROS tests.

Every process started here runs with ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST,
a ROS_DOMAIN_ID reserved for the test alone (domain_coordinator), under
`timeout -k`, and is ended by its own PID when the test finishes.  The Fast DDS
shared-memory segments its processes (and theirs) map are noted while they live
(``shm_watch``), for the tests that ask what a run left; once they have ended,
every Fast DDS file that appeared in /dev/shm during the test and whose owner
has died (a process the test SIGKILLed) is removed (``supervisor.shm``), never
one whose owner lives.
"""

import contextlib
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time

import numpy as np
import pytest
import slot_use
from proc_group import children as _children
from shm_watch import ShmWatch

from polymatch_ros.ros.config.configs import AgentConfig, MonitorConfig, RobotConfig, ros_args

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CONFIG = os.path.join(REPO, "config")
PY = sys.executable


def scene_path(name):
    return os.path.join(CONFIG, name if name.endswith(".yaml") else name + ".yaml")


def ros_available():
    try:
        import rclpy  # noqa: F401
        return True
    except ImportError:
        return False


needs_ros = pytest.mark.skipif(not ros_available(), reason="rclpy is not installed")


class Ros:
    """A test's private ROS world: one domain id, loopback discovery, processes ended by PID."""

    def __init__(self, domain):
        from polymatch_ros.ros.network.environment import private_ros_environment
        from polymatch_ros.ros.supervisor.shm import ShmSweep

        self.domain = domain
        self.env = private_ros_environment(domain)
        assert self.env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
        self.procs = []
        self.shm = ShmWatch(lambda: [p.pid for p in self.procs if p.poll() is None])
        self.sweep = ShmSweep()  # /dev/shm as the world found it

    def start(self, argv, timeout, name="", env=None):
        """Start ``argv`` under `timeout -k 5 <timeout>`; stdout+stderr kept in a temp file;
        ``env``: another environment than the world's (with its ROS_DOMAIN_ID, ``domain``).
        With POLYMATCH_KEEP_LOGS, a `polymatch run` also writes its processes' output
        (``--logs``), kept beside its own when the test fails."""
        argv, run_logs = list(map(str, argv)), None
        if os.environ.get("POLYMATCH_KEEP_LOGS") and argv[2:4] == ["polymatch_ros.cli", "run"]:
            run_logs = tempfile.mkdtemp(prefix="polymatch_run_logs_")
            argv += ["--logs", run_logs]
        log = open(
            os.path.join(
                os.environ.get("TMPDIR", "/tmp"),
                f"polymatch_test_{os.getpid()}_{len(self.procs)}.log",
            ),
            "w+",
        )
        proc = subprocess.Popen(
            ["timeout", "-k", "5", str(timeout)] + list(argv),
            env=self.env if env is None else env,
            stdout=log,
            stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL,
            cwd=REPO,
        )
        proc.log, proc.name, proc.run_logs = log, name, run_logs
        self.procs.append(proc)
        return proc

    def agent(self, scene, agent, timeout=120, **params):
        argv = node_argv("nodes.agent", scene, node=f"agent_{agent}", agent=agent, **params)
        return self.start(argv, timeout, f"agent {agent}")

    def monitor(self, scene, timeout=120, **params):
        return self.start(node_argv("nodes.monitor", scene, node="monitor", **params), timeout,
                          "monitor")

    @staticmethod
    def output(proc):
        proc.log.flush()
        proc.log.seek(0)
        return proc.log.read()

    @staticmethod
    def wait(proc, timeout):
        try:
            return proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            return None

    def kill(self, proc, sig=signal.SIGKILL):
        """Signal one process by PID: the `timeout` wrapper's child too, for SIGKILL."""
        self.shm.look()  # the segments of what is about to end
        if proc.poll() is None:
            if sig == signal.SIGKILL:
                for child in _children(proc.pid):
                    with contextlib.suppress(ProcessLookupError):
                        os.kill(child, signal.SIGKILL)
            with contextlib.suppress(ProcessLookupError):
                os.kill(proc.pid, sig)

    def close(self, keep_logs=None):
        """End every process by PID; with ``keep_logs`` (a directory) keep each one's output."""
        self.shm.look()
        for proc in self.procs:
            if proc.poll() is None:
                self.kill(proc, signal.SIGINT)
        deadline = time.monotonic() + 5
        for proc in self.procs:
            left = max(0.1, deadline - time.monotonic())
            if self.wait(proc, left) is None:
                self.kill(proc, signal.SIGKILL)
                self.wait(proc, 5)
            proc.log.close()
            if keep_logs:
                os.makedirs(keep_logs, exist_ok=True)
                name = (proc.name or "process").replace(" ", "_")
                label = f"{self.procs.index(proc):02d}_{name}"
                shutil.copy(proc.log.name, os.path.join(keep_logs, f"{label}.log"))
                if proc.run_logs:  # the output of each process the run started
                    shutil.copytree(proc.run_logs, os.path.join(keep_logs, label))
            if proc.run_logs:
                shutil.rmtree(proc.run_logs, ignore_errors=True)
            with contextlib.suppress(OSError):
                os.unlink(proc.log.name)
        self.shm.stop()
        self.shm.remove_unheld()
        self.sweep.remove_dead()  # what a process that died during the test left, noted or not

    def shm_left(self):
        """The /dev/shm entries of this world's processes still there (``ShmWatch.left``)."""
        return self.shm.left()


def cli_argv(*args):
    """``polymatch ARGS...`` as this interpreter runs it (every argument as a string)."""
    return [PY, "-m", "polymatch_ros.cli", *map(str, args)]


def placed_vertices(model, groups, origin):
    """Every agent's vertices per group: origin + x_i + O_i times the reference shape."""
    out = []
    for g, gs in zip(model.groups, groups):
        mats = model.rotations.to_matrices(gs.rot)
        out.append(
            gs.x + origin + np.einsum("nij,aj->nai", mats, g.reference).transpose(1, 0, 2)
        )
    return out


#: each node module's configuration (``polymatch_ros.ros.config.configs``)
NODE_CONFIGS = {"nodes.agent": AgentConfig, "nodes.monitor": MonitorConfig,
                "nodes.robot": RobotConfig}


def node_argv(module, scene, node=None, namespace=None, **params):
    """The command line of node ``module`` on ``scene`` with ``params`` (as given: a bad value
    reaches the node, which refuses it), rendered as the runner renders it (``ros_args``)."""
    config = NODE_CONFIGS[module](scene=scene_path(scene), **params)
    return [PY, "-m", f"polymatch_ros.ros.{module}", "--ros-args"] + ros_args(
        config, namespace=namespace, node=node)


# How many tests run ROS worlds at once, across the pytest workers.  Their processes mostly
# wait (discovery, round timeouts, ticks), but a control loop that runs on the wall clock
# (realtime agents, bridged robots) or a round timeout fails when it gets a sliver of a core:
# on two cores four worlds at once kept a load average near 30 while every node process still
# imported its libraries itself; with node processes forked from the runner's fork server
# (``ros/process/forked.py``) three fit.  The other workers run the core's tests meanwhile.
ROS_SLOTS = int(os.environ.get("POLYMATCH_TEST_ROS_SLOTS", "3"))
SLOT_DIR = os.path.join(os.environ.get("TMPDIR", "/tmp"), "polymatch_test_ros_slots")
# The niceness of a slot's processes where the user may raise priorities (root): ahead of the
# other workers' numerical tests, as a robot's control processes run ahead of batch work.  A
# second-order bridged run diverged beside eight busy loops at niceness 0 and converged at -5.
SLOT_NICENESS = -5


@contextlib.contextmanager
def _ahead_of_batch_work():
    """This process (and every process it starts meanwhile) at ``SLOT_NICENESS``, if allowed."""
    before = os.getpriority(os.PRIO_PROCESS, 0)
    try:
        os.setpriority(os.PRIO_PROCESS, 0, SLOT_NICENESS)
    except PermissionError:
        yield
        return
    try:
        yield
    finally:
        os.setpriority(os.PRIO_PROCESS, 0, before)


@contextlib.contextmanager
def ros_slot(slots=ROS_SLOTS, poll=0.2):
    """Hold one of ``slots`` machine-wide slots (an exclusive ``flock`` on one of ``slots``
    files) while the block runs, ahead of batch work (``_ahead_of_batch_work``); wait for one
    while all are held.  The kernel releases the lock of a process that dies, so a crashed
    worker holds nothing.  With POLYMATCH_SLOT_LOG set, each hold is logged (``slot_use``)."""
    import fcntl

    os.makedirs(SLOT_DIR, exist_ok=True)
    while True:
        for i in range(slots):
            fh = open(os.path.join(SLOT_DIR, f"slot_{i}"), "a")
            try:
                fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                fh.close()
                continue
            try:
                with _ahead_of_batch_work(), slot_use.held():
                    yield i
            finally:
                fh.close()  # closing the file drops the lock
            return
        time.sleep(poll)


def _attempt_folder(base):
    """``base``, or ``base_2``, ``base_3``, ... for a test's rerun: each attempt's logs apart."""
    folder, attempt = base, 1
    while os.path.exists(folder):
        attempt += 1
        folder = f"{base}_{attempt}"
    return folder


@pytest.fixture
def ros(request):
    """A private ROS world, in one of ``ROS_SLOTS`` slots; with POLYMATCH_KEEP_LOGS=DIR the
    processes' output of a failed test, and the failure (``failure.txt``), are kept in
    DIR/<test name>/ (what test/support/repeat_tests.py uses to look into a failure)."""
    from domain_coordinator import domain_id

    with ros_slot(), domain_id() as dom:
        world = Ros(dom)
        try:
            yield world
        finally:
            keep = os.environ.get("POLYMATCH_KEEP_LOGS")
            failed = (
                getattr(request.node, "rep_call", None) is not None
                and request.node.rep_call.failed
            )
            folder = (_attempt_folder(os.path.join(keep, request.node.name))
                      if keep and failed else None)
            world.close(folder)
            if folder is not None:  # why it failed, also for a test whose rerun passes
                os.makedirs(folder, exist_ok=True)
                with open(os.path.join(folder, "failure.txt"), "w", encoding="utf-8") as fh:
                    fh.write(request.node.rep_call.longreprtext)
