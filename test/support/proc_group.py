"""Bounded child processes for the discovery and multi-host tests.

Every process runs under ``timeout -k 5 SECONDS`` (after an optional prefix such as
``ip netns exec NAME``, which execs in place, so the PID is the wrapper's), writes its output to
a file in the test's directory, and is ended by its own PID: SIGINT, then SIGKILL of the wrapper
and its child (benchmarks/hosts/runs.py); here they run in the repository and can be
test/support/dds_probe.py.
"""

import os
import sys

from benchmarks.hosts import runs as host_runs
from benchmarks.hosts.runs import children  # noqa: F401 (ros_harness uses it)

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
PROBE = os.path.join(REPO, "test", "support", "dds_probe.py")


class Processes(host_runs.Processes):
    """The processes one test started; ``close`` ends every one of them."""

    def __init__(self, directory):
        super().__init__(directory, cwd=REPO)

    def probe(self, name, env, seconds, prefix=(), **options):
        """Start test/support/dds_probe.py; options become ``--key value`` (lists: several
        values)."""
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
