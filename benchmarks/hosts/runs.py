"""`polymatch run` split over namespace hosts (namespaces.py): bounded processes ended by PID.

    procs = Processes(directory)
    procs.start(argv, env, 60, "h1", prefix=net.prefix(1))     # under timeout -k 5 60
    procs.close()                                              # SIGINT, then SIGKILL, by PID

Every process runs under ``timeout -k 5 SECONDS`` (after an optional prefix such as
``ip netns exec NAME``, which execs in place, so the PID is the wrapper's), writes its output to
a file in ``directory``, and is ended by its own PID: SIGINT, then SIGKILL of the wrapper and its
child.  ``run_on_hosts`` runs one `polymatch run --only ...` per host while tcpdump watches the
root namespace's interfaces for DDS packets.
"""

import contextlib
import os
import signal
import subprocess
import sys
import time

import yaml


def children(pid):
    try:
        with open(f"/proc/{pid}/task/{pid}/children") as fh:
            return [int(child) for child in fh.read().split()]
    except OSError:
        return []


def descendants(pid):
    """PIDs below ``pid`` (children, grandchildren, ...), read from /proc."""
    out, todo = [], [pid]
    while todo:
        for child in children(todo.pop()):
            out.append(child)
            todo.append(child)
    return out


def argv_of(pid):
    """A process's command line as a list of bytes ([] once it has gone)."""
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as fh:
            return fh.read().split(b"\0")
    except OSError:
        return []


def node_name(argv):
    """The node name a ROS process was given (``-r __node:=NAME``), or None."""
    names = [a[len(b"__node:="):].decode() for a in argv if a.startswith(b"__node:=")]
    return names[-1] if names else None


class Processes:
    """The processes one run started; ``close`` ends every one of them."""

    def __init__(self, directory, cwd=None):
        self.directory, self.cwd = directory, cwd
        self.procs = []

    def start(self, argv, env, seconds, name, prefix=()):
        log_path = os.path.join(self.directory, f"{len(self.procs):03d}_{name}.log")
        with open(log_path, "w") as log:
            proc = subprocess.Popen(list(prefix) + ["timeout", "-k", "5", str(seconds)]
                                    + list(argv), env=env, stdout=log,
                                    stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                    cwd=self.cwd)
        proc.log_path, proc.name = log_path, name
        self.procs.append(proc)
        return proc

    @staticmethod
    def output(proc):
        with open(proc.log_path) as log:
            return log.read()

    def wait_for(self, procs, text, seconds):
        """Wait until every process in ``procs`` printed a line starting with ``text``;
        return the ones that did not (in time, or because they ended)."""
        deadline = time.monotonic() + seconds
        waiting = list(procs)
        while waiting and time.monotonic() < deadline:
            waiting = [proc for proc in waiting
                       if not any(line.startswith(text)
                                  for line in self.output(proc).splitlines())]
            if waiting:
                if all(proc.poll() is not None for proc in waiting):
                    break
                time.sleep(0.1)
        return waiting

    def kill(self, proc):
        for child in children(proc.pid):
            with contextlib.suppress(ProcessLookupError):
                os.kill(child, signal.SIGKILL)
        with contextlib.suppress(ProcessLookupError):
            os.kill(proc.pid, signal.SIGKILL)

    def close(self, grace=5.0):
        """SIGINT to every live process by PID; SIGKILL what is left after ``grace`` seconds."""
        for proc in self.procs:
            if proc.poll() is None:
                with contextlib.suppress(ProcessLookupError):
                    os.kill(proc.pid, signal.SIGINT)
        deadline = time.monotonic() + grace
        for proc in self.procs:
            try:
                proc.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                self.kill(proc)
                proc.wait(timeout=5)


def host_argv(scene, only, lead, *options, timeout=100):
    """`polymatch run` of the agents ``only`` on one host; the lead host runs the monitor."""
    argv = [sys.executable, "-m", "polymatch_ros.cli", "run", str(scene), "--only", only,
            "--discovery", "subnet", "--timeout", str(timeout)] + [str(o) for o in options]
    return argv + ([] if lead else ["--no-monitor"])


def host_environment(domain, directory=None):
    """The environment of every host's runner: the shared domain, data over UDPv4 only (shared
    memory would bypass the network between the namespaces); with ``directory``, its temporary
    folder (TMPDIR) there: a runner that is killed leaves its own folder in the run's, not in
    /tmp."""
    env = {k: v for k, v in os.environ.items() if k != "ROS_AUTOMATIC_DISCOVERY_RANGE"}
    env.update(ROS_DOMAIN_ID=str(domain), FASTDDS_BUILTIN_TRANSPORTS="UDPv4",
               PYTHONUNBUFFERED="1")
    if directory is not None:
        env["TMPDIR"] = str(directory)
    return env


def lockstep_split(hosts, n):
    """--only ranges of ``n`` agents split evenly over ``hosts`` hosts."""
    size = n // hosts
    return [f"{i * size}-{(i + 1) * size - 1}" for i in range(hosts)]


def lockstep_argvs(scene_file, n, out, t_end=1.0, timeout=100):
    """Lockstep on three hosts, n/3 agents each, one process per host; the last saves."""
    split = lockstep_split(3, n)
    return [host_argv(scene_file, only, i == 2, "--t-end", t_end, "-k", n // 3,
                      *(["--save", out] if i == 2 else []), timeout=timeout)
            for i, only in enumerate(split)]


def scene_with(directory, name, count):
    """A copy of a scene (file or shipped name) with ``count`` agents in every group, written
    to ``directory`` (seeded: reproducible)."""
    from polymatch_ros.core.scenes.scene import resolve_scene_path

    with open(resolve_scene_path(name)) as fh:
        data = yaml.safe_load(fh)
    for group in data["groups"]:
        group["count"] = count
    path = os.path.join(str(directory), f"{os.path.basename(str(name))}_{count}.yaml")
    with open(path, "w") as fh:
        fh.write(yaml.safe_dump(data))
    return path


def run_on_hosts(net, directory, argvs, during=None, seconds=120, cwd=None):
    """Run ``argvs[i]`` in host i while tcpdump watches the root namespace.

    ``during(procs, started, env)`` runs while they do (loss, a link down, an observer).
    Returns (the processes, their outputs, the root capture (ended), what ``during`` returned);
    every process has ended (by itself or by PID) when it returns or raises.
    """
    from domain_coordinator import domain_id

    from .namespaces import Capture, root_interfaces

    procs, found = Processes(str(directory), cwd), None
    with domain_id() as domain, Capture(str(directory), root_interfaces()) as root:
        env = host_environment(domain, directory)
        try:
            started = [procs.start(argv, env, seconds, f"h{i}", prefix=net.prefix(i))
                       for i, argv in enumerate(argvs)]
            if during is not None:
                found = during(procs, started, env)
            for proc in started:
                proc.wait(timeout=seconds + 10)
            texts = [procs.output(proc) for proc in started]
        finally:
            procs.close()
    return started, texts, root, found
