"""A running node's parameters read back (GetParameters) the values it uses, and a value set
while it runs is the value in use."""

import json
import os
import re
import time

from param_tables import LOCKSTEP_TABLE, RCLPY_OWN, REALTIME_TABLE
from ros_harness import PY, needs_ros, node_argv, scene_path

from polymatch_ros.ros.config.configs import (
    AgentConfig,
    MonitorConfig,
    RecorderConfig,
    RobotConfig,
    config_values,
    ros_args,
)

SECOND = "congruent_triangles_second_order"
PROBE = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "support",
                     "param_probe.py")


@needs_ros
def test_parameters_read_back_what_the_nodes_use_and_a_runtime_set_is_used(ros):
    """`ros2 param get` through GetParameters: a lockstep agent's every parameter is the value it
    uses (the scene's kappa, gamma, integrator, dt, t_end); a realtime agent's shows the
    overrides (gamma, rate) beside the scene's (kappa, mass); the monitor's t_end; a kappa set
    while running reads back and is the gain in use (the agent's diagnostics); read-only ones
    and values out of range are refused."""
    before = time.time()
    ros.start(node_argv("nodes.agent", "congruent_triangles", node="agent_0", agent=0,
                        discovery_timeout=120.0), timeout=90, name="lockstep agent")
    ros.start(node_argv("nodes.agent", SECOND, namespace="/second", node="agent_0", agent=0,
                        mode="realtime", gamma=2.0, rate=5.0), timeout=90, name="realtime agent")
    ros.start(node_argv("nodes.monitor", "congruent_triangles", node="monitor", t_end=12.5),
              timeout=90, name="monitor")
    lock, real = "/polymatch/agent_0", "/second/agent_0"
    probe = ros.start([PY, PROBE, f"get {lock}", f"get {real}", "get /polymatch/monitor",
                       f"diagnostic {real} gamma 2", f"diagnostic {real} kappa 1",
                       f"set {real} kappa 3.0", f"get {real} kappa", f"diagnostic {real} kappa 3",
                       f"set {real} mass 0.0", f"set {real} t_end 5.0", f"set {lock} kappa 3.0",
                       f"get {real} mass t_end", f"get {lock} kappa",
                       f"describe {lock} kappa dt agents", f"describe {real} kappa mass t_end"],
                      timeout=80, name="probe")
    assert ros.wait(probe, 85) == 0, ros.output(probe)
    text = ros.output(probe)
    got = [json.loads(m) for m in re.findall(r"^PARAMS \S+ (.*)$", text, re.M)]
    assert got[0] == dict(LOCKSTEP_TABLE, **RCLPY_OWN), text
    start_time = got[1].pop("start_time")
    assert got[1] == dict(REALTIME_TABLE, **RCLPY_OWN), text
    assert before < start_time < time.time(), text  # declared once t = 0 was fixed
    assert got[2] == dict(scene=scene_path("congruent_triangles"), mode="lockstep", rate=10.0,
                          report_rate=20.0, peer_timeout=1.0, frame_id="world", markers=True,
                          t_end=12.5, run_id=0, agents_per_process=1, report_readers=0,
                          **RCLPY_OWN), text
    assert got[3:] == [{"kappa": 3.0}, {"mass": 0.5, "t_end": 50.0}, {"kappa": 1.0}], text
    sets = re.findall(r"^SET (\S+) (\S+) (True|False) ?(.*)$", text, re.M)
    assert [s[:3] for s in sets] == [(real, "kappa", "True"), (real, "mass", "False"),
                                     (real, "t_end", "False"), (lock, "kappa", "False")], text
    assert "read-only" in sets[2][3] and "read-only" in sets[3][3], text
    described = [json.loads(m) for m in re.findall(r"^DESCRIBE \S+ (.*)$", text, re.M)]
    assert described == [
        {"kappa": {"read_only": True, "range": [0.0, 1e6]},  # lockstep: the scene's model
         "dt": {"read_only": True, "range": [1e-12, 1e6]},
         "agents": {"read_only": True, "range": None}},
        {"kappa": {"read_only": False, "range": [0.0, 1e6]},  # realtime: set while running
         "mass": {"read_only": False, "range": [1e-12, 1e6]},
         "t_end": {"read_only": True, "range": [1e-12, 1e12]}},
    ], text


#: a node that reads the configuration of class argv[1] from its command line and prints it
READ_BACK = """
import json, sys
import rclpy
from rclpy.node import Node
from polymatch_ros.ros.config.configs import CONFIGS, config_values, given_config
rclpy.init(args=sys.argv)
node = Node("read_back", automatically_declare_parameters_from_overrides=False)
cls = next(c for c in CONFIGS if c.__name__ == sys.argv[1])
print(json.dumps(config_values(given_config(node, cls))))
node.destroy_node()
rclpy.shutdown()
"""


@needs_ros
def test_a_configuration_on_a_command_line_is_what_the_node_reads(ros):
    """rcl's own parser is the oracle of the renderer: each configuration, written by
    ``ros_args`` and read by a node (declare and check, as every node does), comes back field
    for field - strings YAML would read as a bool or a number, paths with a space and a colon,
    an integer given for a float, the smallest dt, lists, non-default booleans."""
    configs = [
        AgentConfig(scene=scene_path("congruent_triangles"), agents=[3, 4], mode="realtime",
                    integrator="1e-3", dt=1e-12, rate=7, frame_id="true", peers_restart=True,
                    checkpoint="/tmp/a b:c/x.checkpoint", start="at", start_time=1.7e9,
                    kappa=0.30000000000000004),
        MonitorConfig(scene=scene_path("congruent_triangles"), markers=False, report_readers=3,
                      frame_id="map"),
        RobotConfig(scene=scene_path("congruent_triangles"), agent=5, seed=0, pose_log="yes"),
        RecorderConfig(output="/tmp/run.mcap", duration=2.5, mode="on", t_end=30.0),
    ]
    procs = [ros.start([PY, "-c", READ_BACK, type(c).__name__, "--ros-args"] + ros_args(c),
                       timeout=60, name=type(c).__name__) for c in configs]
    for config, proc in zip(configs, procs):
        assert ros.wait(proc, 65) == 0, ros.output(proc)
        got = json.loads(ros.output(proc).strip().splitlines()[-1])
        want = config_values(config)
        assert got == {k: float(v) if k == "rate" else v for k, v in want.items()}
