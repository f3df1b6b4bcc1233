"""`polymatch run` joins the user's ROS graph: a second shell with the same environment hears it.

The domain the test reserves stands in for the user's: it is set in a user's shell's
environment (ROS_DOMAIN_ID, and ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST as README asks of a
second shell; none of polymatch's transports or profile; every process a test starts stays on
loopback),
`polymatch run` starts there without --isolated, and a plain rclpy process with that same
environment (test/support/graph_reader.py, as `ros2 topic echo` in a second terminal) receives
the diameter and the monitor's run records.  With --isolated the run is in a domain of its own:
`polymatch echo` in the user's domain hears nothing and says where it listened.
"""

import json
import os
import re

from ros_harness import PY, REPO, cli_argv, needs_ros, scene_path

pytestmark = needs_ros

READER = os.path.join(REPO, "test", "support", "graph_reader.py")
SCENE = "congruent_triangles"


def users_shell(domain):
    """A user's shell: the test's environment without any ROS or DDS setting but ROS_DOMAIN_ID
    and loopback discovery (a test never sends DDS traffic beyond loopback)."""
    env = {k: v for k, v in os.environ.items()
           if not k.startswith(("ROS_", "FASTRTPS", "FASTDDS", "RMW_"))}
    env["ROS_DOMAIN_ID"] = str(domain)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    return env


def test_run_in_the_users_domain_is_heard_from_a_second_shell_theorem_4_2(ros):
    """Theorem 4.2 (congruent triangles match): the second shell's reader gets diameters that
    fall, and the monitor's run records; the run's second line names the user's domain."""
    shell = users_shell(ros.domain)
    run = ros.start(cli_argv("run", scene_path(SCENE), "-k", 4, "--hold", 5, "--timeout", 200),
                    timeout=230, name="run", env=shell)
    reader = ros.start([PY, READER, "--count", 3], timeout=120, name="reader", env=shell)
    assert ros.wait(reader, 120) == 0, ros.output(reader)[-3000:] + ros.output(run)[-3000:]
    assert ros.wait(run, 120) == 0, ros.output(run)
    lines = [json.loads(x) for x in ros.output(reader).splitlines() if x.startswith("{")]
    assert lines[0] == {"domain": str(ros.domain), "range": "LOCALHOST"}  # the shell's own
    diameters = [x["diameter"] for x in lines if "diameter" in x]
    roles = [x["status"] for x in lines if "status" in x]
    assert len(diameters) >= 3 and diameters[-1] < diameters[0], diameters
    assert "monitor" in roles, roles
    assert f"ROS graph: domain {ros.domain} (your ROS_DOMAIN_ID)" in ros.output(run)


def test_isolated_run_is_private_and_echo_says_where_it_listened(ros):
    """--isolated: the run reserves another domain, and `polymatch echo` in the user's domain,
    without --timeout, gives up after 10 s (exit 1) naming that domain and its loopback range."""
    shell = users_shell(ros.domain)
    # paced in real time (36 simulated s in 12 wall s): the run lasts while the echo listens,
    # its agents idle between their steps
    run = ros.start(cli_argv("run", scene_path(SCENE), "-k", 4, "--mode", "realtime",
                             "--time-scale", 3, "--rate", 30, "--t-end", 36, "--hold", 1e9,
                             "--timeout", 200, "--isolated"), timeout=230, name="run", env=shell)
    echo = ros.start(cli_argv("echo", "/polymatch/diameter"), timeout=60, name="echo", env=shell)
    assert ros.wait(echo, 60) == 1, ros.output(echo)
    said = ros.output(echo).strip()
    assert said == (f"polymatch: error: no publisher on /polymatch/diameter within 10 s in "
                    f"ROS_DOMAIN_ID {ros.domain}, discovery range LOCALHOST"), said
    assert ros.wait(run, 200) == 0, ros.output(run)
    private = re.search(r"ROS graph: domain (\d+), private to this run", ros.output(run))
    assert private and int(private.group(1)) != ros.domain, ros.output(run)
