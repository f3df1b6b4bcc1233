"""The runner's node processes forked from a fork server (``ros/process/forked.py``) start as
``python -m MODULE ARGS`` started by exec would: the same arguments, command line, environment,
exit codes and output, a process group of their own.  The oracle is Python's own start of the
same module by exec (``subprocess``) and the kernel's ``/proc``.  No ROS process is started:
the module is a stand-in (``test/support/forked_probe.py``)."""

import ast
import multiprocessing
import os
import signal
import subprocess
import sys
import threading

import pytest

from polymatch_ros.ros.process import forked

PROBE = "forked_probe"
SUPPORT = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "support")


@pytest.fixture
def probe_forkable(monkeypatch):
    monkeypatch.setattr(forked, "NODE_MODULES", (*forked.NODE_MODULES, PROBE))


def _env():
    env = dict(os.environ, PROBE_VALUE="a value with spaces", PYTHONUNBUFFERED="1")
    env.pop("PROBE_ABSENT", None)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (SUPPORT, env.get("PYTHONPATH")) if p)
    return env


def _by_exec(args):
    done = subprocess.run([sys.executable, "-m", PROBE, *args], env=_env(), text=True,
                          stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                          stderr=subprocess.STDOUT, process_group=0, timeout=60)
    return done.returncode, done.stdout


def _by_fork(args):
    os.environ["PROBE_ABSENT"] = "the runner's own, not the child's"
    try:
        child = forked.start([sys.executable, "-m", PROBE, *args], _env())
    finally:
        del os.environ["PROBE_ABSENT"]
    assert child is not None
    code = child.wait(timeout=60)
    return code, child.stdout.read()


@pytest.mark.parametrize("args", [["0"], ["3", "--ros-args", "-r", "__node:=agent_3"],
                                  ["message"]])
def test_a_forked_node_process_starts_as_an_execd_one(probe_forkable, args):
    forked_code, forked_text = _by_fork(args)
    exec_code, exec_text = _by_exec(args)
    assert (forked_code, forked_text) == (exec_code, exec_text)
    expected_code = 1 if args == ["message"] else int(args[0])
    assert forked_code == expected_code
    assert f"cmdline {[ '-m', PROBE, *args]}" in forked_text      # what ps shows
    assert "env a value with spaces False" in forked_text
    assert "own group True" in forked_text and "stdin \n" in forked_text
    assert "fd 0 is the null device True" in forked_text


def test_a_forked_process_is_waited_for_and_killed_by_its_pid(probe_forkable):
    child = forked.start([sys.executable, "-m", PROBE, "wait"], _env())
    assert child is not None and child.poll() is None
    with pytest.raises(subprocess.TimeoutExpired):
        child.wait(timeout=0.2)
    os.kill(child.pid, signal.SIGKILL)
    assert child.wait(timeout=30) == -signal.SIGKILL  # as Popen reports a signal
    assert child.poll() == -signal.SIGKILL


def test_only_node_modules_run_by_this_interpreter_are_forked():
    node = "polymatch_ros.ros.nodes.agent"
    assert forked.forkable([sys.executable, "-m", node, "--ros-args"]) == node
    assert forked.forkable(["/usr/bin/python3.9", "-m", node]) is None   # another interpreter
    assert forked.forkable([sys.executable, "-m", "polymatch_ros.cli", "run"]) is None
    assert forked.forkable([sys.executable, "-c", node]) is None
    assert forked.forkable(["timeout", "5", sys.executable, "-m", node]) is None
    assert forked.start(["true"], None) is None


def test_a_command_line_longer_than_the_room_keeps_whole_arguments():
    """``show_command_line`` in a forked copy of this process: ``/proc`` shows the whole
    arguments that fit, never a cut one."""
    read_end, write_end = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: never returns into pytest
        try:
            os.close(read_end)
            long = ["x" * 100] * 1000
            shown = forked.show_command_line(["first", "second", *long])
            with open("/proc/self/cmdline", "rb") as fh:
                os.write(write_end, repr((shown, fh.read())).encode())
        finally:
            os._exit(0)
    os.close(write_end)
    with os.fdopen(read_end, "rb") as fh:
        text = fh.read().decode()
    os.waitpid(pid, 0)
    shown, cmdline = ast.literal_eval(text)
    parts = cmdline.rstrip(b"\0").split(b"\0")
    assert shown and parts[:2] == [b"first", b"second"]
    assert all(part == b"x" * 100 for part in parts[2:]) and len(parts) < 1002


def test_a_fork_server_that_cannot_start_leaves_every_start_to_exec(monkeypatch):
    def no_room():
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(forked, "_server", no_room)
    monkeypatch.setattr(forked, "_unavailable", None)
    node = [sys.executable, "-m", "polymatch_ros.ros.nodes.agent", "--ros-args"]
    assert forked.start(node, None) is None
    assert forked._unavailable == "[Errno 28] No space left on device"
    monkeypatch.setattr(forked, "_server", lambda: pytest.fail("asked the server again"))
    assert forked.start(node, None) is None


def test_a_runs_fork_server_keeps_its_files_in_the_runs_folder_and_ends_with_it(
        probe_forkable, tmp_path):
    """Its socket and ``multiprocessing``'s temporary folder inside the run's folder (which the
    runner removes), and the server and resource tracker ended when the run's block ends (the
    kernel's /proc: no such process)."""
    from multiprocessing import forkserver, resource_tracker, util

    (tmp_path / "earlier").mkdir()
    with forked.fork_server(str(tmp_path / "earlier")):
        pass                                  # ends a server an earlier test of this worker left
    run_folder = tmp_path / "run"
    run_folder.mkdir()
    with forked.fork_server(str(run_folder)):
        child = forked.start([sys.executable, "-m", PROBE, "0"], _env())
        assert child is not None and child.wait(timeout=60) == 0
        server = forkserver._forkserver._forkserver_pid
        tracker = resource_tracker._resource_tracker._pid
        assert os.path.exists(f"/proc/{server}") and os.path.exists(f"/proc/{tracker}")
        assert util.get_temp_dir() == str(run_folder)
        assert forkserver._forkserver._forkserver_address.startswith(str(run_folder) + os.sep)
    assert not os.path.exists(f"/proc/{server}") and not os.path.exists(f"/proc/{tracker}")
    assert "tempdir" not in multiprocessing.current_process()._config


@pytest.mark.parametrize("other_thread", [False, True], ids=["one thread", "two threads"])
def test_a_runs_fork_server_is_the_runners_fork_only_where_the_runner_runs_one_thread(
        probe_forkable, tmp_path, other_thread):
    """Where the runner runs one thread when its run begins (``fork_server``), the server is a
    fork of it: the kernel shows the runner's command line and the runner as its parent (no
    second interpreter imports the node modules again), and it holds none of the runner's files
    but the standard streams.  With another thread running, a fork could copy a lock that
    thread holds: the server is then ``multiprocessing``'s own fresh interpreter.  A child of
    either starts as one started by exec (``_by_exec``, the oracle)."""
    from multiprocessing import forkserver

    stop = threading.Event()
    if other_thread:
        threading.Thread(target=stop.wait, daemon=True).start()
    else:
        assert threading.active_count() == 1  # the case's premise: this worker's only thread
    held, run_folder = tmp_path / "a file of the runner's", tmp_path / "run"
    run_folder.mkdir()
    with open(held, "w"), forked.fork_server(str(run_folder)):
        child = forked.start([sys.executable, "-m", PROBE, "0"], _env())
        assert child is not None
        server = forkserver._forkserver._forkserver_pid
        with open(f"/proc/{server}/cmdline", "rb") as fh:
            server_cmdline = fh.read()
        server_files = {os.readlink(f"/proc/{server}/fd/{n}") for n in os.listdir(
            f"/proc/{server}/fd")}
        code, text = child.wait(timeout=60), child.stdout.read()
    stop.set()
    with open("/proc/self/cmdline", "rb") as fh:
        own_cmdline = fh.read()
    assert (server_cmdline == own_cmdline) is not other_thread
    assert (b"multiprocessing.forkserver" in server_cmdline) is other_thread
    assert str(held) not in server_files
    assert (code, text) == _by_exec(["0"])
