"""`polymatch run --record FILE`: the recorder (``nodes.recorder``) as one more child of the run.

It starts before the monitor and the agents, subscribed at once to every topic of the run
(``wire.recording.run_topics``: types and writer profiles from the topic table), and the
agents wait for it as for the monitor (``pose_subscribers``), so a lockstep recording holds
every step's poses; the monitor waits for its report readers (``report_readers``) before it
reads a pose, so the recording holds every report, the first too.  It is ended last, after
the monitor (and bridge mode's robots), by SIGINT: it takes what its readers still hold,
finishes the file and exits 0; a recorder that died or failed is the run's error.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Sequence
from typing import TYPE_CHECKING

from .. import wire
from ..config.configs import RecorderConfig, ros_args
from ..wire.recording import run_topics
from .children import Child
from .plan import RunPlan

if TYPE_CHECKING:
    from ..network.discovery import DiscoveryEnvironments

#: SIGINT to SIGTERM: its drain (1 s), the file's summary, the DDS teardown
RECORDER_GRACE_SECONDS = 10.0


def recorder_argv(plan: RunPlan, directory: str) -> list[str]:
    """The recorder's command line for ``plan`` (``plan.outputs.record`` set); its topic lists
    go in a parameter file in ``directory`` (thousands of agents exceed what one command-line
    argument may hold)."""
    import yaml

    assert plan.outputs.record is not None  # only called with --record
    topics = run_topics(plan.hosts.ensemble, plan.n_agents, plan.scene.model.dim,
                        plan.scene.model.order, plan.hosts.monitor)
    lists = {"topics": [t.name for t in topics], "types": [t.type for t in topics],
             "qos": [t.qos for t in topics]}
    params = os.path.join(directory, "recorder_params.yaml")
    with open(params, "w", encoding="utf-8") as fh:
        yaml.safe_dump({"/**": {"ros__parameters": lists}}, fh)
    config = RecorderConfig(output=os.path.abspath(plan.outputs.record),
                            scene_file=os.path.abspath(plan.scene_path), t_end=plan.scene.t_end,
                            mode=plan.mode.value)
    return [sys.executable, "-m", "polymatch_ros.ros.nodes.recorder", "--ros-args"] + ros_args(
        config, namespace=wire.namespace(plan.hosts.ensemble), node="recorder",
        params_file=params)


def start_recorder(plan: RunPlan, env: dict[str, str], envs: DiscoveryEnvironments | None,
                   directory: str) -> list[Child]:
    """[the recorder child], started ([] without --record); with a discovery server
    (``envs``) a super client, as the monitor, so that it sees every topic; ``directory``: the
    run's private one."""
    if plan.outputs.record is None:
        return []
    child = Child("recorder", recorder_argv(plan, directory),
                  env if envs is None else envs.for_role("super_client", env),
                  log_dir=plan.outputs.logs)
    child.stop_grace = RECORDER_GRACE_SECONDS
    return [child]


def report_recording(children: Sequence[Child], code: int, quiet: bool) -> int:
    """After the recorder among ``children`` (if any) was stopped: print what it wrote
    (unless ``quiet``) or how it failed; the run's exit code (a failed recording fails a run
    that had succeeded)."""
    recorder = next((c for c in children if c.name == "recorder"), None)
    if recorder is None:
        return code
    last = next((line for line in reversed(recorder.tail(20))
                 if line.startswith("recorder: ")), "")
    if recorder.poll() == 0 and last.startswith("recorder: recorded"):
        if not quiet:
            print(last.removeprefix("recorder: "))
        return code
    print(f"polymatch run: error: the recorder failed (exit code {recorder.poll()}): "
          f"{last or ' | '.join(recorder.tail(2))}", file=sys.stderr)
    return code or 1
