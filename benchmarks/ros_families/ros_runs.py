"""Runs of `polymatch` for the families that measure the ROS node set (trade, distributed,
graphs): a scene file in the run's directory, the command under ``timeout``, and the agents'
run records it wrote."""

import contextlib
import os
import subprocess
import sys
import tempfile


@contextlib.contextmanager
def private_runs():
    """(a temporary directory, the ROS environment of a domain reserved for as long as the
    runs last): where a family writes its scenes and how it starts `polymatch`."""
    from domain_coordinator import domain_id

    from polymatch_ros.ros.network.environment import private_ros_environment

    with tempfile.TemporaryDirectory() as workdir, domain_id() as dom:
        yield workdir, private_ros_environment(dom)


def write_scene(directory, name, text):
    """Write the scene ``text`` to ``directory/name``; return the path."""
    path = os.path.join(directory, name)
    with open(path, "w") as fh:
        fh.write(text)
    return path


def run_cli(env, argv, timeout):
    """`python -m polymatch_ros.cli ARGV` under ``timeout -k 5 TIMEOUT``; its CompletedProcess
    with the output as text."""
    return subprocess.run(
        ["timeout", "-k", "5", str(timeout), sys.executable, "-m", "polymatch_ros.cli"] + argv,
        env=env,
        capture_output=True,
        text=True,
    )


def agent_records(path):
    """The agents' run records a `polymatch run --run-records` wrote (none if the run failed
    early)."""
    from polymatch_ros.ros.wire import run_records

    if not os.path.exists(path):
        return []
    with open(path, encoding="utf-8") as fh:
        return [r for r in run_records(fh) if r.role == "agent"]


def run_parallel(argvs, env, timeout):
    """Start every command of ``argvs`` at once under ``timeout -k 5 TIMEOUT``; the output of
    each (stdout and stderr together), in order, once all have ended."""
    procs = [
        subprocess.Popen(["timeout", "-k", "5", str(timeout)] + argv, env=env,
                         stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        for argv in argvs
    ]
    outs = []
    for p in procs:
        try:
            out, _ = p.communicate(timeout=timeout + 10)
        except subprocess.TimeoutExpired:
            p.kill()
            out, _ = p.communicate()
        outs.append(out)
    return outs
