"""`polymatch run SCENE`: a whole distributed ensemble from one scene file, without launch.

Starts the monitor and one process per agent (or per K agents), all with
loopback discovery and a fresh ROS_DOMAIN_ID unless the user set them; shows
progress (simulated time, diameter, rounds/s); stops at t_end or once the
diameter has stayed under the scene's tolerance; prints a summary (final
diameters per group, in lockstep the deviation from the centralised solution,
wall time, rounds/s); and ends every process it started, by PID, also on
Ctrl-C and when a child dies.
"""

import os
import random
import signal
import subprocess
import sys
import threading
import time
from collections import deque
from dataclasses import replace

import numpy as np

from . import wire
from ..console import SUMMARY_HEADER, Progress, format_table, positive_float, summary_rows
from ..core.errors import PolymatchError
from ..core.scene import load_scene, resolve_scene_path
from ..core.metrics import ensemble_metrics
from ..core.model import GroupState, State
from ..core.simulate import convergence_verdict, plan, prepare, simulate
from .ros_env import hung_in_teardown, reserved_domain_id, ros_environment, teardown_watchdog


def _die_with_parent():
    """In the child, before exec: get SIGTERM if the runner dies (Linux), so nothing outlives it."""
    try:
        import ctypes
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGTERM)   # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


class Child:
    """A supervised process: output kept (last lines) and echoed on failure; ended by its own PID."""

    def __init__(self, name, argv, env):
        self.name = name
        self.proc = subprocess.Popen(argv, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                     stdin=subprocess.DEVNULL, start_new_session=True, text=True, bufsize=1,
                                     preexec_fn=_die_with_parent)
        self.lines = deque(maxlen=200)
        self.thread = threading.Thread(target=self._read, daemon=True)
        self.thread.start()

    def _read(self):
        for line in self.proc.stdout:
            self.lines.append(line.rstrip("\n"))

    @property
    def pid(self):
        return self.proc.pid

    def poll(self):
        return self.proc.poll()

    def stop(self, grace=3.0):
        """SIGINT, then SIGTERM, then SIGKILL — each to this child's PID only."""
        for sig, wait in ((signal.SIGINT, grace), (signal.SIGTERM, 2.0), (signal.SIGKILL, 2.0)):
            if self.proc.poll() is not None:
                break
            try:
                os.kill(self.proc.pid, sig)
            except ProcessLookupError:
                break
            try:
                self.proc.wait(timeout=wait)
            except subprocess.TimeoutExpired:
                continue
        self.thread.join(timeout=1.0)
        return self.proc.poll()

    def tail(self, n=5):
        return list(self.lines)[-n:]

    def hung_in_teardown(self):
        """Reported its final line, then its DDS teardown hung and its watchdog ended it."""
        return hung_in_teardown(self.proc.poll(), list(self.lines))

    def ended_well(self):
        return self.proc.poll() == 0 or self.hung_in_teardown()


def partition(n_agents, k):
    return [list(range(s, min(s + k, n_agents))) for s in range(0, n_agents, k)]


class Watcher:
    """The runner's own small node.

    It hears the headline diameter and the monitor's and agents' diagnostics (progress,
    agents heard), publishes the control topic, and takes each agent's *final* pose from
    its latched ``final_pose``/``final_twist`` topics for the summary — not the per-step
    poses, so supervising a run adds no load to the lockstep rounds.
    """

    def __init__(self, scene, ensemble):
        from diagnostic_msgs.msg import DiagnosticArray
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.node import Node
        from std_msgs.msg import Float64, String
        self.node = Node("polymatch_runner")
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)
        self.scene, self.model = scene, scene.model
        self.grp = self.model.rotations
        self.ensemble = ensemble
        qos = wire.qos_profiles()
        self.diameter = None
        self.monitor_t = None
        self.monitor_heard = 0
        self.agent_t = {}                # agent -> simulated time from its diagnostics
        self.node.create_subscription(Float64, wire.ensemble_topic(ensemble, "diameter"), self._diam, qos["latched"])
        self.node.create_subscription(DiagnosticArray, "/diagnostics", self._diag, 50)
        self.control = self.node.create_publisher(String, wire.ensemble_topic(ensemble, "control"), qos["control"])
        self.poses = {}
        self.velocities = {}
        dim = self.model.dim
        if dim <= 3:
            from geometry_msgs.msg import PoseStamped, TwistStamped
            pose_t, twist_t = PoseStamped, TwistStamped
        else:
            from std_msgs.msg import Float64MultiArray
            pose_t = twist_t = Float64MultiArray
        for a in range(self.model.n_agents):
            self.node.create_subscription(pose_t, wire.agent_topic(ensemble, a, "final_pose"), self._pose(a),
                                          qos["latched"])
            if self.model.order == 2:
                self.node.create_subscription(twist_t, wire.agent_topic(ensemble, a, "final_twist"), self._twist(a),
                                              qos["latched"])

    def _diam(self, msg):
        self.diameter = float(msg.data)

    def _diag(self, msg):
        prefix = f"polymatch/{self.ensemble}/"
        for st in msg.status:
            if not st.name.startswith(prefix):
                continue
            values = {kv.key: kv.value for kv in st.values}
            try:
                t = float(values.get("t", "nan"))
            except ValueError:
                continue
            if st.name == prefix + "monitor":
                self.monitor_t = t
                self.monitor_heard = int(values.get("agents_heard", "0"))
            elif st.hardware_id.startswith("agents "):
                for a in st.hardware_id[len("agents "):].split(","):
                    if a.strip().isdigit():
                        self.agent_t[int(a)] = t

    def _pose(self, agent):
        def receive(msg):
            got, _ = wire.decode_pose_msg(msg, self.grp, self.model.dim)
            if got is not None:
                self.poses[agent] = (got.t, got.vec - self.scene.origin, got.rot)
        return receive

    def _twist(self, agent):
        def receive(msg):
            got, _ = wire.decode_twist_msg(msg, self.grp, self.model.dim)
            if got is not None:
                self.velocities[agent] = (got.vec, got.rot)
        return receive

    def spin(self, timeout):
        self.executor.spin_once(timeout_sec=timeout)

    def agents_up(self):
        return len(self.agent_t) >= self.model.n_agents

    def ensemble_time(self):
        """Simulated time of the ensemble: the monitor's last report, else the slowest agent's."""
        if self.monitor_t is not None:
            return self.monitor_t
        if len(self.agent_t) < self.model.n_agents:
            return None
        return min(self.agent_t.values())

    def all_heard(self):
        """The monitor's last report covered every agent."""
        return self.monitor_heard >= self.model.n_agents

    def pose_times(self):
        """Simulated time of every agent's final pose."""
        return {a: p[0] for a, p in self.poses.items()}

    def have_final(self):
        return len(self.poses) >= self.model.n_agents and (
            self.model.order == 1 or len(self.velocities) >= self.model.n_agents)

    def stop(self):
        from std_msgs.msg import String
        self.control.publish(String(data="stop"))

    def start(self, epoch):
        from std_msgs.msg import String
        self.control.publish(String(data=f"start {epoch!r}"))

    def final_state(self):
        """The final pose of every agent as a core State (None if some agent never reported)."""
        if len(self.poses) < self.model.n_agents:
            return None
        groups = []
        for g in self.model.groups:
            x = np.array([self.poses[a][1] for a in g.indices])
            rot = self.grp.concat([self.poses[a][2] for a in g.indices])
            v = w = None
            if self.model.order == 2 and all(a in self.velocities for a in g.indices):
                v = np.array([self.velocities[a][0] for a in g.indices])
                w = self.grp.algebra_concat([self.velocities[a][1] for a in g.indices])
            groups.append(GroupState(x, rot, v, w))
        return State(min(p[0] for p in self.poses.values()), tuple(groups))

    def destroy(self):
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()


def vertex_deviation(model, a, b):
    """max over agents and vertices of |x^i_a(a) - x^i_a(b)|."""
    worst = 0.0
    grp = model.rotations
    for g, ga, gb in zip(model.groups, a.groups, b.groups):
        for r in g.reference:
            pa = ga.x + grp.rotate(ga.rot, r)
            pb = gb.x + grp.rotate(gb.rot, r)
            worst = max(worst, float(np.max(np.linalg.norm(pa - pb, axis=1))))
    return worst


# rmw_fastrtps, under ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST, probes the first 32 participant
# ports on 127.0.0.1 (its UDP maxInitialPeersRange): two participants beyond that never meet.
LOCALHOST_PARTICIPANTS = 32


def fewest_agents_per_process(n_agents, own):
    """Agents per process that keep ``own`` + the agent processes within LOCALHOST_PARTICIPANTS."""
    return -(-n_agents // (LOCALHOST_PARTICIPANTS - own))


def _agents_per_process(args, n_agents, localhost):
    """-k as given (checked against the participant limit), or 1 if it fits, else the fewest that fit."""
    own = 1 + (1 if args.monitor else 0)                      # the runner's node, the monitor
    need = fewest_agents_per_process(n_agents, own)
    if args.agents_per_process is None:
        if localhost and need > 1:
            if not args.quiet:
                print(f"polymatch run: {n_agents} agents + {own} own processes exceed the {LOCALHOST_PARTICIPANTS} "
                      f"DDS participants LOCALHOST discovery reaches: {need} agents per process (-k {need})",
                      file=sys.stderr)
            return need
        return 1
    procs = -(-n_agents // args.agents_per_process)
    if localhost and procs + own > LOCALHOST_PARTICIPANTS:
        raise PolymatchError(f"{procs} agent processes + {own} own = {procs + own} DDS participants, but LOCALHOST "
                             f"discovery reaches {LOCALHOST_PARTICIPANTS} per domain (rmw_fastrtps' initial-peer "
                             f"range); use -k {need} or more")
    return args.agents_per_process


def cmd_run(args):
    scene_path = resolve_scene_path(args.scene)
    scene = load_scene(scene_path, {"time.t_end": args.t_end})
    rt = args.mode == "realtime"
    dt = args.time_scale / args.rate if rt else args.dt
    the_plan = plan(scene, args.integrator, dt, distributed=True)     # one-line errors before spawning
    if args.agents_per_process is not None and args.agents_per_process < 1:
        raise PolymatchError("--agents-per-process must be >= 1")
    with reserved_domain_id() as domain:
        env = ros_environment(domain, mode=args.mode)
        args.agents_per_process = _agents_per_process(args, scene.model.n_agents,
                                                      env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST")
        for key in ("ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_DOMAIN_ID", "RMW_IMPLEMENTATION",
                    "FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_BUILTIN_TRANSPORTS"):
            if key in env:
                os.environ[key] = env[key]
        return _run(args, scene, scene_path, the_plan, env, domain)


def _run(args, scene, scene_path, the_plan, env, domain):
    import rclpy
    from rclpy.signals import SignalHandlerOptions
    rt = args.mode == "realtime"
    n = scene.model.n_agents
    run_id = random.randrange(1, 2 ** 31 - 1)
    ens = args.ensemble
    common = ["-p", f"scene:={os.path.abspath(scene_path)}", "-p", f"ensemble:={ens}",
              "-p", f"t_end:={scene.t_end!r}", "-p", f"mode:={args.mode}"]
    agent_args = common + ["-p", f"run_id:={run_id}", "-p", f"agents_per_process:={args.agents_per_process}",
                           "-p", f"pose_subscribers:={1 if args.monitor else 0}",
                           "-p", f"integrator:={the_plan.name}",
                           "-p", f"round_timeout:={args.round_timeout!r}",
                           # start-up of many processes on few cores takes a while: scale the patience
                           "-p", f"discovery_timeout:={30.0 + 2.0 * len(partition(n, args.agents_per_process))!r}",
                           "-p", f"peer_timeout:={args.peer_timeout!r}"]
    if rt:
        agent_args += ["-p", f"rate:={args.rate!r}", "-p", f"time_scale:={args.time_scale!r}",
                       "-p", "start_time:=-1.0", "-p", f"delay:={args.delay!r}"]
    else:
        agent_args += ["-p", f"dt:={the_plan.dt!r}"]
    py = [sys.executable, "-m"]
    quiet = args.quiet
    say = (lambda *a: None) if quiet else (lambda *a: print(*a, file=sys.stderr, flush=True))
    say(f"polymatch run: {n} agents in {len(partition(n, args.agents_per_process))} processes, {args.mode}, "
        f"integrator {the_plan.name}, dt {the_plan.dt:g}, ROS_DOMAIN_ID={domain}, "
        f"discovery {env['ROS_AUTOMATIC_DISCOVERY_RANGE']}")
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    children, monitor, watcher = [], None, None
    interrupted = []
    old = {s: signal.signal(s, lambda sig, frame: interrupted.append(sig)) for s in (signal.SIGINT, signal.SIGTERM)}
    start = time.monotonic()
    code, message = 1, "not started"
    try:
        watcher = Watcher(scene, ens)
        if args.monitor:
            mon_args = common + ["-p", f"peer_timeout:={args.peer_timeout!r}"]
            if rt:
                mon_args += ["-p", "rate:=10.0"]
            monitor = Child("monitor", py + ["polymatch_ros.ros.monitor_node", "--ros-args"] + mon_args
                            + ["-r", "__node:=polymatch_monitor"], env)
        for agents in partition(n, args.agents_per_process):
            name = f"agent_{agents[0]}" if len(agents) == 1 else f"agents_{agents[0]}_{agents[-1]}"
            sel = ["-p", f"agent:={agents[0]}"] if len(agents) == 1 else \
                ["-p", "agents:=[" + ",".join(map(str, agents)) + "]"]
            children.append(Child(name, py + ["polymatch_ros.ros.agent_node", "--ros-args"] + agent_args + sel
                                  + ["-r", f"__node:={name}"], env))
        code, message = _supervise(args, scene, the_plan, watcher, children, monitor, interrupted, start, say)
    finally:
        for c in children:
            c.stop()
        if monitor is not None:
            t0 = time.monotonic()
            while watcher is not None and time.monotonic() - t0 < 0.5:
                watcher.spin(0.05)
            monitor.stop()
        for s, h in old.items():
            signal.signal(s, h)
    wall = time.monotonic() - start
    try:
        final = watcher.final_state() if watcher is not None else None
        if code == 0 and final is not None:
            code, message = _summary(args, scene, the_plan, final, children, monitor, wall, quiet, watcher)
        elif message:
            print(f"polymatch: error: {message}", file=sys.stderr)
        for c in children + ([monitor] if monitor is not None else []):
            if c.hung_in_teardown():
                print(f"note: {c.name} reported its result, then its DDS teardown hung (a rare Fast DDS "
                      f"shutdown spin); its watchdog ended it", file=sys.stderr)
    finally:
        sys.stdout.flush()
        sys.stderr.flush()
        with teardown_watchdog():
            if watcher is not None:
                watcher.destroy()
            if rclpy.ok():
                rclpy.shutdown()
    return code


def _supervise(args, scene, the_plan, watcher, children, monitor, interrupted, start, say):
    progress = Progress(scene.t_end, args.quiet)
    rounds_per_step = max(1, the_plan.method.info.rounds)
    deadline = start + args.timeout
    below_since = None
    stop_sent = 0.0
    rate_mark = None
    rps = 0.0
    started = args.mode != "realtime"
    while True:
        watcher.spin(0.05)
        if not started and watcher.agents_up():
            watcher.start(time.time() + 0.5)       # every agent is up: start the clock together
            started = True
        if interrupted:
            progress.done()
            return 130, "interrupted: stopped every process"
        failed = [c for c in children if not c.ended_well() and c.poll() is not None]
        if monitor is not None and not monitor.ended_well() and monitor.poll() is not None:
            failed.append(monitor)
        if failed:
            progress.done()
            c = failed[0]
            detail = " | ".join(line for line in c.tail(3) if line.strip())
            return 1, f"{c.name} (pid {c.pid}) exited with code {c.poll()}: {detail}"
        if all(c.ended_well() for c in children):
            drain = time.monotonic() + 3.0          # the latched final poses may still be in flight
            while time.monotonic() < drain and not watcher.have_final():
                watcher.spin(0.05)
            progress.done()
            return 0, ""
        if time.monotonic() > deadline:
            progress.done()
            return 1, f"timed out after {args.timeout:g} s (raise --timeout)"
        t = watcher.ensemble_time()
        d = watcher.diameter
        if t is not None and d is not None:
            now = time.monotonic()
            if rate_mark is None:
                rate_mark = (now, t)
            elif now - rate_mark[0] > 1.0:
                rps = (t - rate_mark[1]) / max(the_plan.dt, 1e-12) * rounds_per_step / (now - rate_mark[0])
                if args.mode == "realtime":
                    rps = (t - rate_mark[1]) / the_plan.dt / (now - rate_mark[0])
                rate_mark = (now, t)
            progress(t, d, f"  {rps:7.1f} rounds/s")
            if d < scene.tolerance and watcher.all_heard():
                below_since = t if below_since is None else below_since
                if t - below_since >= args.hold and now - stop_sent > 0.5:
                    watcher.stop()
                    stop_sent = now
            else:
                below_since = None


def _summary(args, scene, the_plan, final, children, monitor, wall, quiet, watcher):
    met = ensemble_metrics(scene.model, final)
    print(f"scene {scene.name}: {scene.model.n_agents} agents, {args.mode}, integrator {the_plan.name}, "
          f"dt {the_plan.dt:g}")
    print(format_table(summary_rows(scene, met), SUMMARY_HEADER))
    agent_lines = [line for c in children for line in c.lines if line.startswith("agent ")]
    rates = []
    for line in agent_lines:
        if "rounds/s" in line:
            try:
                rates.append(float(line.split("rounds, ")[1].split(" rounds/s")[0]))
            except (IndexError, ValueError):
                pass
    dropped = [line for line in agent_lines if "; dropped" in line]
    text = f"t = {final.t:g}, wall time {wall:.2f} s"
    if rates:
        text += f", {np.mean(rates):.1f} rounds/s per agent (mean)"
    print(text)
    for line in (agent_lines if args.verbose else dropped):
        print(line)
    if monitor is not None and args.mode == "lockstep":
        for line in monitor.lines:
            if line.startswith("monitor:"):
                print(line)
    if args.save:
        data = {"t": final.t, "origin": scene.origin}
        times = watcher.pose_times()
        for gi, g in enumerate(scene.model.groups):
            data[f"group{gi}_times"] = np.array([times[a] for a in g.indices])
        for gi, gs in enumerate(final.groups):
            data[f"group{gi}_centroids"] = gs.x + scene.origin
            data[f"group{gi}_rotations"] = scene.model.rotations.to_matrices(gs.rot)
        np.savez(args.save, **data)
        print(f"final poses (as received on the pose topics) saved to {args.save}")
    if args.mode == "lockstep" and args.compare:
        ref = simulate(replace(scene, t_end=final.t), the_plan.name, the_plan.dt, samples=[final.t],
                       keep_states=False, metrics=False)
        central = prepare(scene, the_plan)
        dev = vertex_deviation(central.model, ref.final, _as_rep(central.model, scene.model, final))
        print(f"lockstep vs centralised simulation (same integrator and dt) at t = {final.t:g}: "
              f"max vertex deviation {dev:.3e}")
    converged_at = final.t if met.diameter < scene.tolerance else None
    code, msg = convergence_verdict(scene, met.diameter, converged_at)
    print(msg)
    return code, msg


def _as_rep(target_model, model, state):
    if type(target_model.rotations) is type(model.rotations):
        return state
    src, dst = model.rotations, target_model.rotations
    return State(state.t, tuple(GroupState(gs.x, dst.from_matrices(src.to_matrices(gs.rot)), gs.v, None)
                                for gs in state.groups))


def add_parser(sub):
    p = sub.add_parser("run", help="run the distributed ROS 2 ensemble of a scene (one process per agent)")
    p.add_argument("scene", help="scene file or shipped scene name")
    p.add_argument("--mode", choices=("lockstep", "realtime"), default="lockstep")
    p.add_argument("--integrator", "-i", metavar="NAME", help="fixed-step integrator (default: the scene's)")
    p.add_argument("--dt", type=positive_float, help="lockstep step size (default: the scene's)")
    p.add_argument("--t-end", type=positive_float, help="override time.t_end")
    p.add_argument("--agents-per-process", "-k", type=int, default=None, metavar="K",
                   help="agents per process (default 1, or the fewest that keep the processes within the 32 "
                        "DDS participants that LOCALHOST discovery reaches)")
    p.add_argument("--rate", type=positive_float, default=50.0, help="realtime: steps per second (default 50)")
    p.add_argument("--time-scale", type=positive_float, default=1.0,
                   help="realtime: simulated seconds per wall-clock second")
    p.add_argument("--peer-timeout", type=positive_float, default=1.0, help="realtime: drop silent peers after S s")
    p.add_argument("--delay", type=float, default=0.0, help="realtime: injected transport delay (s), experiments")
    p.add_argument("--round-timeout", type=positive_float, default=10.0, help="lockstep: give up a round after S s")
    p.add_argument("--hold", type=float, default=1.0,
                   help="stop once the diameter stayed under the tolerance this long (simulated s)")
    p.add_argument("--timeout", type=positive_float, default=600.0, help="wall-clock limit for the whole run (s)")
    p.add_argument("--ensemble", default="polymatch", help="ensemble namespace (default polymatch)")
    p.add_argument("--no-monitor", dest="monitor", action="store_false", help="do not start the monitor")
    p.add_argument("--no-compare", dest="compare", action="store_false",
                   help="lockstep: skip the comparison with the centralised simulation")
    p.add_argument("--save", metavar="NPZ", help="save the final poses received from the agents (npz)")
    p.add_argument("--quiet", "-q", action="store_true")
    p.add_argument("--verbose", "-v", action="store_true", help="print every agent's final line")
    p.set_defaults(func=cmd_run)
