"""Recordings: ``polymatch record TOPICS... -o FILE`` and ``polymatch plot FILE``.

    polymatch record /polymatch/agent_0/pose /polymatch/diameter -o run.mcap --duration 30
    polymatch plot run.mcap --figure run.png --at 0,3,6

``record`` runs the recorder node (``ros.nodes.recorder``) in this process, in the caller's
ROS environment, until --duration, Ctrl-C or SIGTERM; ``polymatch run --record FILE`` starts
the same node as one more process of the run.  ``plot`` reads a recording without ROS
(``ros.wire.recording_read``) and prints a table, or draws the diameters against simulated
time and snapshots of the polytopes (``figures.recording_figure``).
"""

from __future__ import annotations

import argparse
import math
import os
from dataclasses import replace
from typing import TYPE_CHECKING

from ..console import format_table, positive_float, writable_output
from ..core.errors import ParameterError

if TYPE_CHECKING:
    from ..ros.wire.recording_read import Recording, Series

#: rows of the diameter table when no --at times are given
TABLE_ROWS = 8


def cmd_record(args: argparse.Namespace) -> int:
    """Check the arguments, then run the recorder; it ends this process with its code."""
    for topic in args.topics:
        if not topic.startswith("/") or len(topic) < 2 or "," in topic:
            raise ParameterError(f"topic must be an absolute name (start with /), got {topic!r}")
    from ..ros.config.configs import RecorderConfig, ros_args

    config = RecorderConfig(output=os.path.abspath(writable_output(args.output, ".mcap")),
                            duration=args.duration or 0.0)
    if args.scene is not None:
        from ..core.scenes.scene import load_scene, resolve_scene_path

        scene_file = resolve_scene_path(args.scene)
        load_scene(scene_file)  # a bad scene is an error now, not an unreadable recording
        config = replace(config, scene_file=os.path.abspath(scene_file))
    from ..ros.nodes.recorder import main

    return main(["polymatch record", "--ros-args"] + ros_args(
        config, node=f"record_{os.getpid()}", lists={"topics": args.topics}))


def time_list(text: str) -> list[float]:
    """``--at 0,3,6`` -> [0.0, 3.0, 6.0] (finite, >= 0)."""
    try:
        values = [float(part) for part in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected times like 0,3,6, got {text!r}") from None
    if not all(math.isfinite(v) and v >= 0 for v in values):
        raise argparse.ArgumentTypeError(f"times must be finite and >= 0, got {text!r}")
    return values


def cmd_plot(args: argparse.Namespace) -> int:
    """A table of the recording (topics, diameters), or with --figure its PNG."""
    from ..core.metrics import ensemble_metrics
    from ..ros.wire.recording_read import diameter_series, read_recording, states_at

    figure = writable_output(args.figure, ".png") if args.figure else None
    rec = read_recording(args.recording)
    series = diameter_series(rec)
    if figure is None:
        print(_describe(rec, series, args.at))
        return 0
    from ..figures import recording_figure

    t0, t1 = float(series.t[0]), float(series.t[-1])
    scene = rec.scene
    times = args.at
    if times is None and scene is not None:
        times = [t for t in scene.snapshots if t0 <= t <= t1] or [t0, t1]
    states = states_at(rec, times or [])
    snapshots = [(st.t, st, ensemble_metrics(scene.model, st).diameter)
                 for st in states] if scene is not None else []
    curves = [("matching diameter", series.matching), ("centroid diameter", series.centroid),
              ("rotation diameter", series.rotation)]
    title = f"{scene.name}: {os.path.basename(rec.path)}" if scene else rec.path
    recording_figure(series.t, curves, figure, scene, snapshots, title,
                     f"diameters from the {series.source}")
    print(f"figure saved to {figure}")
    return 0


def _describe(rec: Recording, series: Series, at: list[float] | None) -> str:
    """The recording's topics and its diameters at ``at`` (else TABLE_ROWS times)."""
    import numpy as np

    scene = f"scene {rec.scene.name}" if rec.scene is not None else "no scene attached"
    lines = [f"{rec.path}: {sum(t.messages for t in rec.topics)} messages over "
             f"{rec.duration:.1f} s of wall-clock time, {scene}", ""]
    lines.append(format_table([[t.topic, t.type, t.messages] for t in rec.topics],
                              ["topic", "type", "messages"]))
    if at is None:
        rows = np.unique(np.linspace(0, len(series.t) - 1, TABLE_ROWS).round().astype(int))
    else:
        rows = np.unique([max(0, int(np.searchsorted(series.t, t, side="right")) - 1)
                          for t in at])
    lines += ["", f"diameters (from the {series.source}):"]
    lines.append(format_table(
        [[f"{series.t[i]:g}", f"{series.matching[i]:.3e}", f"{series.centroid[i]:.3e}",
          f"{series.rotation[i]:.3e}"] for i in rows],
        ["t", "matching", "centroid", "rotation"]))
    return "\n".join(lines)


def add_parser(sub: argparse._SubParsersAction) -> None:
    """The ``record`` and ``plot`` subcommands."""
    p = sub.add_parser("record", help="record topics of a running ensemble to an MCAP file "
                                      "(ROS 2 CDR messages with their schemas)")
    p.add_argument("topics", nargs="+", metavar="TOPIC", help="absolute topic names")
    p.add_argument("-o", "--output", required=True, metavar="MCAP", help="the file to write")
    p.add_argument("--duration", type=positive_float, metavar="S",
                   help="stop after S seconds (default: at Ctrl-C or SIGTERM)")
    p.add_argument("--scene", help="attach this scene file: `polymatch plot` then computes the "
                                   "diameters from the poses and draws the polytopes")
    p.set_defaults(func=cmd_record)

    p = sub.add_parser("plot", help="diameters against time and snapshots from a recording "
                                    "(`polymatch run --record`, `polymatch record`)")
    p.add_argument("recording", help="an MCAP file")
    p.add_argument("--figure", metavar="PNG", help="draw it (needs matplotlib)")
    p.add_argument("--at", type=time_list, metavar="T1,T2,...",
                   help="snapshot times (default: the scene's figure.snapshots); without "
                        "--figure, the table's times")
    p.set_defaults(func=cmd_plot)
