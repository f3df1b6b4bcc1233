"""The parameters a lockstep and a realtime agent declare, with their values: what the
parameter checks compute (test/contract/test_params.py) and what a running node reads back
(test/ros/test_params_over_ros.py)."""

import os

from ros_harness import CONFIG

# every parameter a lockstep agent on congruent_triangles declares, with its value (no
# placeholder: no 0 for "the scene's", no '' for "none"); rclpy adds use_sim_time and
# start_type_description_service
LOCKSTEP_TABLE = {
    "scene": os.path.join(CONFIG, "congruent_triangles.yaml"), "agent": 0, "agents": [0],
    "agents_per_process": 1, "agent_nodes": "full", "mode": "lockstep", "autostart": True,
    "integrator": "rkmk4",
    "dt": 0.05, "t_end": 30.0, "rate": 50.0, "kappa": 1.0, "gamma": 1.0, "time_scale": 1.0,
    "peer_timeout": 1.0, "delay": 0.0, "clock_offset_warn": 0.1, "hold_final": 0.0,
    "round_timeout": 10.0, "stall_timeout": 300.0, "peers_restart": False,
    "discovery_timeout": 120.0, "pose_subscribers": 0, "exchange_subscribers": 0,
    "exchange_rate": 40.0,
    "frame_id": "world",
    "max_linear_speed": 1e6, "max_angular_speed": 1e6, "max_linear_accel": 1e6,
    "max_angular_accel": 1e6, "pose_timeout": 0.5, "pose_type": "pose",
    "cmd_type": "twist_stamped",
    "command_frame": "world", "drive": "holonomic", "axle_offset": 0.2, "safety_radius": 0.0,
    "safety_alpha": 0.0, "safety_latency": 0.05, "safety_stale": 0.5, "run_id": 0,
}
# a realtime agent on congruent_triangles_second_order given gamma:=2.0 and rate:=5.0: no dt (it
# steps time_scale/rate), the scene's mass, how it starts (start_time: once it started)
REALTIME_TABLE = dict(
    {k: v for k, v in LOCKSTEP_TABLE.items() if k != "dt"},
    scene=os.path.join(CONFIG, "congruent_triangles_second_order.yaml"), mode="realtime",
    t_end=50.0, gamma=2.0, mass=0.5, rate=5.0, discovery_timeout=30.0, start="now",
)
RCLPY_OWN = {"use_sim_time": False, "start_type_description_service": True}
