"""Runs across three network-namespace hosts, and the checks the host tests share."""

import re
import time

import numpy as np
from exactness import central_vertices, received_vertices
from netns_hosts import provided_hosts
from proc_group import REPO

from benchmarks.hosts import runs as netns_run
from benchmarks.hosts.runs import host_argv, lockstep_split
from polymatch_ros.core.scenes.scene import load_scene
from polymatch_ros.core.stepping.simulate import choose_numerics
from polymatch_ros.ros.wire import echoed_run_records

DEVIATION = re.compile(r"max vertex deviation (\S+)")

REALTIME_SCENE = "congruent_triangles"          # first order, 12 agents: 4/4/4
AGENTS = 12
# realtime: 20 steps per wall-clock second hold 12 agents, the monitor and an echo on 2 loaded
# cores (test_ros_realtime.py); time scale 3 gives h = 0.15, under which the centralised run of
# this scene reaches its tolerance at t ~ 19
RATE, TIME_SCALE, T_END = 20.0, 3.0, 120.0
PEER_TIMEOUT = 1.0            # s: agents and the monitor drop a peer silent this long


def three_hosts(tools=("tcpdump",)):
    """The body of a ``net`` fixture: three namespace hosts (skips without root or ``tools``)."""
    yield from provided_hosts(3, tools)


def run_on_hosts(net, tmp_path, argvs, during=None, seconds=120, check=True):
    """Run ``argvs[i]`` in host i while tcpdump watches the root namespace.

    ``during(procs, started, env)`` runs while they do (loss, a link down, an observer).
    Returns (the processes, their outputs, the root capture (ended), what ``during`` returned);
    ``check``: every run ended with 0 or 3.
    """
    started, texts, root, found = netns_run.run_on_hosts(net, tmp_path, argvs, during, seconds,
                                                         cwd=REPO)
    for proc, text in zip(started, texts):
        assert not check or proc.returncode in (0, 3), f"{proc.name}:\n{text[-3000:]}"
    return started, texts, root, found


def check_lockstep_on_hosts(scene_file, texts, out, n):
    """The non-lead hosts' lines, the lead's summary and saved poses equal the centralised run
    to 1e-9 (the lead host is the last)."""
    split = lockstep_split(len(texts), n)
    for text, only in zip(texts[:-1], split):
        assert f"agents {only} ended at t = " in text and "max vertex deviation" not in text
    lead = texts[-1]
    assert f"{n} of {n} agents" not in lead and f"{n // len(texts)} of {n} agents " in lead
    deviation = DEVIATION.search(lead)
    assert deviation and float(deviation.group(1)) <= 1e-9, lead[-3000:]
    scene = load_scene(scene_file)
    t, got = received_vertices(scene, out)
    assert t > 0.0
    want = central_vertices(scene, choose_numerics(scene, None, None, distributed=True).name, t)
    dev = max(float(abs(a - b).max()) for a, b in zip(got, want))
    assert dev <= 1e-9, f"max vertex deviation {dev:.3e}"


def realtime_argvs(scene_file, out, *options, t_end=T_END, timeout=100):
    """Realtime on three hosts, 4 agents (one process) each; the lead (host 2) saves."""
    return [host_argv(scene_file, f"{4 * i}-{4 * i + 3}", i == 2, "--mode", "realtime",
                      "--rate", RATE, "--time-scale", TIME_SCALE, "--t-end", t_end, "-k", 4,
                      "--peer-timeout", PEER_TIMEOUT, "--run-records", f"{out}.h{i}.jsonl",
                      *options, *(["--save", out] if i == 2 else []), timeout=timeout)
            for i in range(3)]


def saved_diameter(scene_file, out):
    """The matching diameter of the final poses the lead host saved: max over groups, agents
    i, j and vertices a of |x^i_a - x^j_a| (the groups are congruent)."""
    _, vertices = received_vertices(load_scene(scene_file), out)
    # vertices[g][a, i] is vertex a of agent i
    return max(float(np.linalg.norm(v[:, :, None] - v[:, None, :], axis=-1).max())
               for v in vertices)


def status_records(procs, echo):
    """The monitor's run records among those ``polymatch echo`` of the status topic printed so
    far (the agents publish theirs there too)."""
    lines = procs.output(echo).splitlines()
    records = echoed_run_records(lines)
    return [r for r in records if r.role == "monitor"]


def wait_for_record(procs, echo, holds, seconds):
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline and echo.poll() is None:
        if any(holds(r) for r in status_records(procs, echo)):
            return True
        time.sleep(0.1)
    return False
