"""Bounded child processes for the discovery and multi-host tests.

Every process runs under ``timeout -k 5 SECONDS`` (after an optional prefix such as
``ip netns exec NAME``, which execs in place, so the PID is the wrapper's), writes its output to
a file in the test's directory, and is ended by its own PID: SIGINT, then SIGKILL of the wrapper
and its child.
"""

import contextlib
import os
import signal
import subprocess
import sys
import time

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PROBE = os.path.join(REPO, "test", "dds_probe.py")


def children(pid):
    try:
        with open(f"/proc/{pid}/task/{pid}/children") as fh:
            return [int(child) for child in fh.read().split()]
    except OSError:
        return []


class Processes:
    """The processes one test started; ``close`` ends every one of them."""

    def __init__(self, directory):
        self.directory = directory
        self.procs = []

    def start(self, argv, env, seconds, name, prefix=()):
        log_path = os.path.join(self.directory, f"{len(self.procs):03d}_{name}.log")
        with open(log_path, "w") as log:
            proc = subprocess.Popen(list(prefix) + ["timeout", "-k", "5", str(seconds)]
                                    + list(argv), env=env, stdout=log,
                                    stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, cwd=REPO)
        proc.log_path, proc.name = log_path, name
        self.procs.append(proc)
        return proc

    def probe(self, name, env, seconds, prefix=(), **options):
        """Start test/dds_probe.py; options become ``--key value`` (lists: several values)."""
        argv = [sys.executable, PROBE, "--name", name, "--seconds", str(seconds)]
        for key, value in options.items():
            flag = "--" + key.replace("_", "-")
            if value is True:
                argv.append(flag)
            elif isinstance(value, (list, tuple)):
                argv += [flag] + [str(item) for item in value]
            else:
                argv += [flag, str(value)]
        return self.start(argv, env, seconds + 10, name, prefix)

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
