"""ROS naming: every node lives in its ensemble's namespace (`/polymatch/agent_3`,
`/polymatch/monitor`), and two ensembles with different names run side by side in one
domain without a duplicate node name (seen through rclpy's graph API from a test node)."""

import json
import textwrap

from ros_harness import PY, needs_ros, scene_path

from benchmarks.hosts.runs import scene_with
from polymatch_ros.ros.network.environment import RESERVED_DOMAIN

pytestmark = needs_ros

PROBE = textwrap.dedent("""
    import json, sys
    import rclpy
    from rclpy.node import Node
    want = set(json.loads(sys.argv[1]))
    rclpy.init()
    node = Node("graph_probe")
    union, twice, missing = set(), set(), None
    while not want <= union:              # every node seen at least once (the runs overlap)
        rclpy.spin_once(node, timeout_sec=0.2)
        names = [ns.rstrip("/") + "/" + n for n, ns in node.get_node_names_and_namespaces()]
        union.update(names)
        twice.update(n for n in names if names.count(n) > 1)
        if want - union != missing:
            missing = want - union
            print("missing " + " ".join(sorted(missing)), flush=True)
    print("GRAPH " + json.dumps({"seen": sorted(union), "twice": sorted(twice)}), flush=True)
    node.destroy_node()
    rclpy.shutdown()
""")


def test_nodes_in_the_ensemble_namespace_and_two_ensembles_coexist(ros, tmp_path):
    # four agents an ensemble (the scene's triangles): names, not numbers, are under test
    scene = scene_with(tmp_path, scene_path("congruent_triangles"), 4)
    first = [f"/polymatch/agent_{i}" for i in range(4)] + [
        "/polymatch/monitor",
        "/polymatch/runner",
    ]
    # packed 2 a process: each agent is its own node too, here a lean one (``agents/hosted.py``)
    second = ["/second/agents_0_1", "/second/agents_2_3", "/second/monitor", "/second/runner"]
    second += [f"/second/agent_{i}" for i in range(4)]
    probe = ros.start([PY, "-c", PROBE, json.dumps(first + second)], timeout=200)
    runs = [
        ros.start(
            [
                PY,
                "-m",
                "polymatch_ros.cli",
                "run",
                scene,
                "-q",
                "--ensemble",
                name,
                "-k",
                k,
                "--timeout",
                "180",
                "--no-compare",
                "--round-timeout",
                "60",
                "--t-end",  # naming is under test: a few steps, not the whole convergence
                "3",
                "--agent-nodes",
                nodes,
            ],
            timeout=200,
        )  # two ensembles on 2 cores
        for name, k, nodes in (("polymatch", "1", "auto"), ("second", "2", "lean"))
    ]
    for run in runs:
        rc = ros.wait(run, 210)
        assert rc in (0, 3), ros.output(run)
        assert "taken twice" not in ros.output(run)
    assert ros.wait(probe, 30) == 0, ros.output(probe)
    line = [x for x in ros.output(probe).splitlines() if x.startswith("GRAPH ")][-1]
    graph = json.loads(line[len("GRAPH ") :])
    assert set(first + second) <= set(graph["seen"]), graph
    assert graph["twice"] == [], graph  # no duplicate node name
    assert not [n for n in graph["seen"] if n.count("/") == 1 and "agent" in n], (
        graph
    )  # none at the root


def test_a_second_run_of_the_same_ensemble_refuses_before_it_starts_a_process(ros):
    """The same scene and ensemble name in the same (user-given) domain while a run is going:
    the second ``polymatch run`` refuses in one line, starts no process, and the first run
    goes on to converge."""
    import time

    from ros_harness import cli_argv

    # the user's domain: not marked reserved for one run (as the harness's is), so each run
    # looks for another ensemble before it starts
    shared = {k: v for k, v in ros.env.items() if k != RESERVED_DOMAIN}
    # four agents a process: the names that collide are the runner's and the monitor's
    first = ros.start(cli_argv("run", scene_path("congruent_triangles"), "-k", "4",
                               "--timeout", "150"), timeout=170, name="first", env=shared)
    deadline = time.monotonic() + 90
    while "t = " not in ros.output(first) and time.monotonic() < deadline:
        time.sleep(0.2)  # its agents are up once it shows progress
    assert first.poll() is None and "t = " in ros.output(first), ros.output(first)[-2000:]
    second = ros.start(cli_argv("run", scene_path("congruent_triangles"), "-k", "4",
                                "--timeout", "60"), timeout=80, name="second", env=shared)
    assert ros.wait(second, 90) == 1, ros.output(second)
    errors = [line for line in ros.output(second).splitlines() if "error" in line]
    assert len(errors) == 1 and errors[0].startswith(
        "polymatch: error: an ensemble named 'polymatch' already runs in this ROS domain"
    ) and "nothing started" in errors[0], ros.output(second)
    assert "[agent_" not in ros.output(second) and "t = " not in ros.output(second)
    assert ros.wait(first, 160) == 0, ros.output(first)[-3000:]
    assert "converged" in ros.output(first)
