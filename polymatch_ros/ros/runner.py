"""`polymatch run SCENE`: a whole distributed ensemble from one scene file, without launch.

Starts the monitor and one process per agent (or per K agents) in the ensemble's namespace
(``-r __ns:=/<ensemble>``, nodes ``agent_<i>`` and ``monitor``), all with loopback discovery
and a fresh ROS_DOMAIN_ID unless the user set them; shows progress (simulated time,
diameter, rounds/s); stops at t_end or once the diameter has stayed under the scene's
tolerance; prints a summary (final diameters per group, in lockstep the deviation from the
centralised solution, wall time, rounds/s) from the agents' final poses and run records; and
ends every process it started, by PID, also on Ctrl-C and when a child dies.
"""

import os
import random
import signal
import sys
import time

from ..console import Progress, positive_float, writable_output
from ..core.errors import PolymatchError
from ..core.scene import load_scene, resolve_scene_path
from ..core.simulate import plan
from . import wire
from .children import (  # noqa: F401 (API)
    LOCALHOST_PARTICIPANTS,
    Child,
    _agents_per_process,
    fewest_agents_per_process,
    partition,
    stop_all,
)
from .ros_env import reserved_domain_id, ros_environment, teardown_watchdog
from .summary import report, verdict
from .watcher import Watcher


def _check_ensemble(name):
    from rclpy.exceptions import InvalidNamespaceException
    from rclpy.validate_namespace import validate_namespace

    try:
        validate_namespace(wire.namespace(name))
    except InvalidNamespaceException:
        raise PolymatchError(
            f"--ensemble: {name!r} is not a valid ROS namespace "
            f"(letters, digits, underscores; not starting with a digit)"
        ) from None


def cmd_run(args):
    scene_path = resolve_scene_path(args.scene)
    scene = load_scene(scene_path, {"time.t_end": args.t_end})
    rt = args.mode == "realtime"
    dt = args.time_scale / args.rate if rt else args.dt
    the_plan = plan(scene, args.integrator, dt, distributed=True)  # one-line errors first
    if args.save:
        args.save = writable_output(args.save, ".npz")     # checked before a long run
    if args.agents_per_process is not None and args.agents_per_process < 1:
        raise PolymatchError("--agents-per-process must be >= 1")
    _check_ensemble(args.ensemble)
    with reserved_domain_id() as domain:
        env = ros_environment(domain, mode=args.mode)
        args.agents_per_process = _agents_per_process(
            args, scene.model.n_agents, env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
        )
        for key in ("ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_DOMAIN_ID", "RMW_IMPLEMENTATION",
                    "FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_BUILTIN_TRANSPORTS"):
            if key in env:
                os.environ[key] = env[key]
        return _run(args, scene, scene_path, the_plan, env, domain)


def _node_args(args, scene, scene_path, the_plan):
    """(--ros-args of the monitor, of every agent process) without the node's own remaps."""
    n = scene.model.n_agents
    common = [
        "-r",
        f"__ns:={wire.namespace(args.ensemble)}",
        "-p",
        f"scene:={os.path.abspath(scene_path)}",
        "-p",
        f"t_end:={scene.t_end!r}",
        "-p",
        f"mode:={args.mode}",
    ]
    agent = common + [
        "-p",
        f"run_id:={random.randrange(1, 2**31 - 1)}",
        "-p",
        f"agents_per_process:={args.agents_per_process}",
        "-p",
        f"pose_subscribers:={1 if args.monitor else 0}",
        "-p",
        f"integrator:={the_plan.name}",
        "-p",
        f"round_timeout:={args.round_timeout!r}",
        # start-up of many processes on few cores takes a while: scale the patience
        "-p",
        f"discovery_timeout:={30.0 + 2.0 * len(partition(n, args.agents_per_process))!r}",
        "-p",
        f"peer_timeout:={args.peer_timeout!r}",
    ]
    if args.mode == "realtime":
        agent += [
            "-p",
            f"rate:={args.rate!r}",
            "-p",
            f"time_scale:={args.time_scale!r}",
            "-p",
            "start_time:=-1.0",
            "-p",
            f"delay:={args.delay!r}",
        ]
    else:
        agent += ["-p", f"dt:={the_plan.dt!r}"]
    monitor = common + ["-p", f"peer_timeout:={args.peer_timeout!r}"]
    if args.mode == "realtime":
        monitor += ["-p", "rate:=10.0"]
    return monitor, agent


def _start(args, scene, scene_path, the_plan, env):
    """(monitor or None, agent children): every process of the ensemble, started."""
    mon_args, agent_args = _node_args(args, scene, scene_path, the_plan)
    py = [sys.executable, "-m"]
    monitor = None
    if args.monitor:
        monitor = Child(
            "monitor",
            py
            + ["polymatch_ros.ros.monitor_node", "--ros-args"]
            + mon_args
            + ["-r", "__node:=monitor"],
            env,
        )
    children = []
    for agents in partition(scene.model.n_agents, args.agents_per_process):
        name = f"agent_{agents[0]}" if len(agents) == 1 else f"agents_{agents[0]}_{agents[-1]}"
        sel = (
            ["-p", f"agent:={agents[0]}"]
            if len(agents) == 1
            else ["-p", "agents:=[" + ",".join(map(str, agents)) + "]"]
        )
        children.append(
            Child(
                name,
                py
                + ["polymatch_ros.ros.agent_node", "--ros-args"]
                + agent_args
                + sel
                + ["-r", f"__node:={name}"],
                env,
            )
        )
    return monitor, children


def _run(args, scene, scene_path, the_plan, env, domain):
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    n = scene.model.n_agents
    say = (lambda *a: None) if args.quiet else (lambda *a: print(*a, file=sys.stderr, flush=True))
    say(
        f"polymatch run: {n} agents in {len(partition(n, args.agents_per_process))} processes, "
        f"{args.mode}, "
        f"integrator {the_plan.name}, dt {the_plan.dt:g}, ROS_DOMAIN_ID={domain}, "
        f"discovery {env['ROS_AUTOMATIC_DISCOVERY_RANGE']}, "
        f"ensemble {wire.namespace(args.ensemble)}"
    )
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    children, monitor, watcher = [], None, None
    interrupted = []
    old = {
        s: signal.signal(s, lambda sig, frame: interrupted.append(sig))
        for s in (signal.SIGINT, signal.SIGTERM)
    }
    start = time.monotonic()
    code, message = 1, "not started"
    progress = Progress(scene.t_end, args.quiet)
    try:
        watcher = Watcher(scene, args.ensemble)
        monitor, children = _start(args, scene, scene_path, the_plan, env)
        run = Supervision(args, scene, the_plan, watcher, children, monitor, progress)
        code, message = run.watch(interrupted, start)
    except PolymatchError as exc:
        code, message = exc.exit_code, str(exc)
    finally:
        stop_all(children, monitor, watcher)
        for s, h in old.items():
            signal.signal(s, h)
    try:
        report(
            args,
            scene,
            the_plan,
            watcher,
            children,
            monitor,
            progress,
            code,
            message,
            time.monotonic() - start,
        )
        code = code if code != 0 or watcher.final_state() is None else verdict(scene, watcher)
    finally:
        sys.stdout.flush()
        sys.stderr.flush()
        with teardown_watchdog():
            if watcher is not None:
                watcher.destroy()
            if rclpy.ok():
                rclpy.shutdown()
    return code


class Supervision:
    """The runner's loop: progress, start (realtime), stop on convergence, failures, the end."""

    def __init__(self, args, scene, the_plan, watcher, children, monitor, progress):
        self.args, self.scene, self.plan = args, scene, the_plan
        self.watcher, self.children, self.monitor, self.progress = (
            watcher,
            children,
            monitor,
            progress,
        )
        self.rounds_per_step = (
            1 if args.mode == "realtime" else max(1, the_plan.method.info.rounds)
        )
        self.rate_mark, self.rps = None, 0.0
        self.below_since, self.stop_sent = None, 0.0
        self.graph_checked = False

    def failure(self):
        """The first child that ended badly, as (code, message), or None."""
        failed = [c for c in self.children if not c.ended_well() and c.poll() is not None]
        if (
            self.monitor is not None
            and not self.monitor.ended_well()
            and self.monitor.poll() is not None
        ):
            failed.append(self.monitor)
        if not failed:
            return None
        c = failed[0]
        detail = " | ".join(line for line in c.tail(3) if line.strip())
        return 1, f"{c.name} (pid {c.pid}) exited with code {c.poll()}: {detail}"

    def check_graph(self):
        """Once every agent is up: its node and the monitor are in the ensemble's namespace."""
        if self.graph_checked or not self.watcher.agents_up():
            return
        names = [c.name for c in self.children] + (["monitor"] if self.monitor is not None else [])
        self.graph_checked = self.watcher.check_graph(names)

    def start_clock(self):
        """Realtime: once every agent is up, 'start <epoch>' for all; repeated (same epoch) each
        second while an agent has not begun stepping - one whose control reader matched late
        would otherwise wait forever (agents take the first 'start' only)."""
        now = time.monotonic()
        if self.epoch is None:
            if self.watcher.agents_up():
                self.epoch, self.start_sent = time.time() + 0.5, now
                self.watcher.start(self.epoch)
        elif now - self.start_sent > 1.0 and any(
            r.steps == 0 and not r.finished for r in self.watcher.agents.values()
        ):
            self.start_sent = now
            self.watcher.start(self.epoch)

    def watch(self, interrupted, start):
        watcher, args = self.watcher, self.args
        self.epoch, self.start_sent = None, 0.0
        while True:
            watcher.spin(0.05)
            if args.mode == "realtime":
                self.start_clock()
            self.check_graph()
            if interrupted:
                self.progress.done()
                return 130, "interrupted: stopped every process"
            failed = self.failure()
            if failed:
                self.progress.done()
                return failed
            if all(c.ended_well() for c in self.children):
                drain = time.monotonic() + 3.0  # the latched final poses may still be in flight
                while time.monotonic() < drain and not watcher.have_final():
                    watcher.spin(0.05)
                return 0, ""
            if time.monotonic() > start + args.timeout:
                self.progress.done()
                return 1, f"timed out after {args.timeout:g} s (raise --timeout)"
            self.show_progress()

    def show_progress(self):
        t, d = self.watcher.ensemble_time(), self.watcher.diameter
        if t is None or d is None:
            return
        now = time.monotonic()
        if self.rate_mark is None or t < self.rate_mark[1]:
            self.rate_mark = (now, t)  # (re)start the rate where the ensemble's time is
        elif now - self.rate_mark[0] > 1.0:
            steps = (t - self.rate_mark[1]) / max(self.plan.dt, 1e-12)
            self.rps = steps * self.rounds_per_step / (now - self.rate_mark[0])
            self.rate_mark = (now, t)
        self.progress(t, d, f"  {self.rps:7.1f} rounds/s")
        if d < self.scene.tolerance and self.watcher.all_heard():
            self.below_since = t if self.below_since is None else self.below_since
            if t - self.below_since >= self.args.hold and now - self.stop_sent > 0.5:
                self.watcher.stop()
                self.stop_sent = now
        else:
            self.below_since = None


def add_parser(sub):
    p = sub.add_parser(
        "run", help="run the distributed ROS 2 ensemble of a scene (one process per agent)"
    )
    p.add_argument("scene", help="scene file or shipped scene name")
    p.add_argument("--mode", choices=("lockstep", "realtime"), default="lockstep")
    p.add_argument("--integrator", "-i", metavar="NAME",
                   help="fixed-step integrator (default: the scene's)")
    p.add_argument("--dt", type=positive_float, help="lockstep step size (default: the scene's)")
    p.add_argument("--t-end", type=positive_float, help="override time.t_end")
    p.add_argument(
        "--agents-per-process",
        "-k",
        type=int,
        default=None,
        metavar="K",
        help="agents per process (default 1, or the fewest that keep the processes within the 32 "
        "DDS participants that LOCALHOST discovery reaches)",
    )
    p.add_argument("--rate", type=positive_float, default=50.0,
                   help="realtime: steps per second (default 50)")
    p.add_argument("--time-scale", type=positive_float, default=1.0,
                   help="realtime: simulated seconds per wall-clock second")
    p.add_argument("--peer-timeout", type=positive_float, default=1.0,
                   help="realtime: drop silent peers after S s")
    p.add_argument("--delay", type=float, default=0.0,
                   help="realtime: injected transport delay (s), experiments")
    p.add_argument("--round-timeout", type=positive_float, default=10.0,
                   help="lockstep: give up a round after S s")
    p.add_argument(
        "--hold",
        type=float,
        default=1.0,
        help="stop once the diameter stayed under the tolerance this long (simulated s)",
    )
    p.add_argument("--timeout", type=positive_float, default=600.0,
                   help="wall-clock limit for the whole run (s)")
    p.add_argument("--ensemble", default="polymatch",
                   help="ensemble namespace (default polymatch)")
    p.add_argument("--no-monitor", dest="monitor", action="store_false",
                   help="do not start the monitor")
    p.add_argument("--no-compare", dest="compare", action="store_false",
                   help="lockstep: skip the comparison with the centralised simulation")
    p.add_argument("--save", metavar="NPZ",
                   help="save the final poses received from the agents (npz)")
    p.add_argument("--quiet", "-q", action="store_true")
    p.add_argument("--verbose", "-v", action="store_true", help="print every agent's final line")
    p.add_argument("--records", metavar="JSONL",
                   help="write every process's run record (JSON, one a line) to this file")
    p.set_defaults(func=cmd_run)
