"""Every agent is its own node at any packing (``agents/hosted.py``).

A process hosting several agents is the node ``agents_<first>_<last>`` and gives each agent a
lean node ``agent_<i>``: seen through rclpy's graph API, as ``ros2 node list``, ``ros2 topic
info -v``, ``ros2 service call`` and ``ros2 param`` see them, during a realtime run of 8 agents
in 2 processes (-k 4).
"""

import json
import os
import re
import textwrap

from ros_harness import PY, cli_argv, needs_ros, scene_path

pytestmark = needs_ros

SUPPORT = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "support")

# every node of the ensemble, and the node that publishes each agent's pose
GRAPH = textwrap.dedent("""
    import json, time
    import rclpy
    from rclpy.node import Node
    rclpy.init()
    node = Node("agent_node_probe")
    want = {f"agent_{i}" for i in range(8)} | {"agents_0_3", "agents_4_7"}
    end, names, owners = time.monotonic() + 60, set(), {}
    while time.monotonic() < end and not (want <= names and len(owners) == 8):
        rclpy.spin_once(node, timeout_sec=0.2)
        names = {n for n, ns in node.get_node_names_and_namespaces() if ns == "/polymatch"}
        for i in range(8):
            info = node.get_publishers_info_by_topic(f"/polymatch/agent_{i}/pose")
            if info:
                owners[i] = sorted(p.node_name for p in info)
    print("GRAPH " + json.dumps({"names": sorted(names), "owners": owners}), flush=True)
""")


def _probes(ros, probes):
    """Start every probe at once (each waits for the nodes it asks, up to its own bound);
    each one's output once all have ended well."""
    procs = {name: ros.start(argv, timeout=90, name=name) for name, argv in probes.items()}
    for proc in procs.values():
        assert ros.wait(proc, 100) == 0, ros.output(proc)
    return {name: ros.output(proc) for name, proc in procs.items()}


def test_every_agent_of_a_packed_process_is_a_node_with_its_topics_services_and_parameters(
        ros, tmp_path):
    logs = tmp_path / "logs"
    # the probes start with the run and ask it as soon as its nodes are there; at time scale 2
    # the run converges (and stops) seconds after its agents start
    run = ros.start(cli_argv("run", scene_path("congruent_triangles"), "--mode", "realtime",
                             "--rate", "20", "--time-scale", "2", "-k", "4", "--t-end", "30",
                             "--timeout", "120", "--no-compare", "--logs", logs),
                    timeout=140, name="run")
    out = _probes(ros, {
        "graph": [PY, "-c", GRAPH],
        "services": [PY, os.path.join(SUPPORT, "service_probe.py"),
                     "call /polymatch/agent_5/pause true", "call /polymatch/agent_5/pause false"],
        "params": [PY, os.path.join(SUPPORT, "param_probe.py"),
                   "get /polymatch/agent_5 agent agents host_node mode agents_per_process",
                   "set /polymatch/agent_5 t_end 5.0",
                   "get /polymatch/agents_4_7 agent agents"],
    })
    graph = json.loads(re.search(r"^GRAPH (.*)$", out["graph"], re.M).group(1))
    names = set(graph["names"])
    assert {f"agent_{i}" for i in range(8)} | {"agents_0_3", "agents_4_7"} <= names, graph
    # each pose topic has one writer: the agent's own node
    assert graph["owners"] == {str(i): [f"agent_{i}"] for i in range(8)}, graph

    calls = out["services"]
    answers = re.findall(r"^RESULT /polymatch/agent_5/pause (\S+) (.*)$", calls, re.M)
    assert [a[0] for a in answers] == ["True", "True"], calls
    assert all("applied by its process /polymatch/agents_4_7 to the 4 agents it hosts" in a[1]
               for a in answers), calls

    params = out["params"]
    got = [json.loads(m) for m in re.findall(r"^PARAMS \S+ (.*)$", params, re.M)]
    assert got[0] == {"agent": 5, "agents": [4, 5, 6, 7], "host_node": "/polymatch/agents_4_7",
                      "mode": "realtime", "agents_per_process": 4}, params
    assert got[1] == {"agent": 4, "agents": [4, 5, 6, 7]}, params
    assert re.search(r"^SET /polymatch/agent_5 t_end False .*read-only", params, re.M), params

    assert ros.wait(run, 130) == 0, ros.output(run)[-3000:]
    assert "converged" in ros.output(run)
    if not os.environ.get("POLYMATCH_KEEP_LOGS"):  # else the harness gave it a --logs of its own
        _assert_logs(logs)


def _assert_logs(logs):
    """--logs: each process's whole output, its pause and its final run record among it."""
    assert sorted(p.name for p in logs.iterdir()) == ["agents_0_3.log", "agents_4_7.log",
                                                       "monitor.log"]
    text = (logs / "agents_4_7.log").read_text()
    assert "service pause: paused" in text and '"role": "agent"' in text, text[-2000:]
