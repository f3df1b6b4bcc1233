"""Runs across three network-namespace hosts, and the checks the host tests share."""

import re

from exactness import central_vertices, received_vertices
from netns_hosts import provided_hosts
from proc_group import REPO

from benchmarks.hosts import runs as netns_run
from benchmarks.hosts.runs import lockstep_split
from polymatch_ros.core.scene import load_scene
from polymatch_ros.core.simulate import plan

DEVIATION = re.compile(r"max vertex deviation (\S+)")


def three_hosts(tools=("tcpdump",)):
    """The body of a ``net`` fixture: three namespace hosts (skips without root or ``tools``)."""
    yield from provided_hosts(3, tools)


def run_on_hosts(net, tmp_path, argvs, during=None, seconds=120):
    """Run ``argvs[i]`` in host i while tcpdump watches the root namespace.

    ``during(procs, started, env)`` runs while they do (loss, a link down, an observer).
    Returns (the processes, their outputs, the root capture (ended), what ``during`` returned).
    """
    started, texts, root, found = netns_run.run_on_hosts(net, tmp_path, argvs, during, seconds,
                                                         cwd=REPO)
    for proc, text in zip(started, texts):
        assert proc.returncode in (0, 3), f"{proc.name}:\n{text[-3000:]}"
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
    want = central_vertices(scene, plan(scene, None, None, distributed=True).name, t)
    dev = max(float(abs(a - b).max()) for a, b in zip(got, want))
    assert dev <= 1e-9, f"max vertex deviation {dev:.3e}"
