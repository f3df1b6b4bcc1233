"""The runner's children: a process group of their own (a terminal's Ctrl-C is the runner's to
handle), the runner's session (one scheduling group: Linux's autogroups gave each session its
own, and lockstep processes in separate ones waited about twice as long for each other), and
ended with the runner.
"""

import os
import sys

from polymatch_ros.ros.supervisor.children import Child

REPORT = "import os; print(os.getpgid(0), os.getsid(0), flush=True)"


def test_a_child_has_its_own_process_group_in_the_runners_session():
    child = Child("probe", [sys.executable, "-c", REPORT], dict(os.environ))
    assert child.proc.wait(timeout=30) == 0
    child.stop()
    pgid, sid = (int(v) for v in child.tail(1)[0].split())
    assert pgid == child.pid  # its own group: the terminal's SIGINT goes to the runner's
    assert pgid != os.getpgid(0)
    assert sid == os.getsid(0)  # not a session (a scheduling group) of its own
