"""Two lockstep exchanges in one process, one stage message lost on the way.

    python test/support/lost_stage.py SCENE STEPS [--no-resend]

Agents 0-3 and 4-7 of SCENE are driven by two ``LockstepExchange`` objects in two threads,
exactly as two agent processes drive them (``LockstepAgent.loop``), for STEPS rkmk4 steps.
Each side sends one block message a round (``stage_links.BlockLinks``).  The first message
of block 0 (agents 0-3) for round (step 1, stage 2) is swallowed before it reaches DDS: a
sample lost for good, as one can be when a starved peer is matched anew.  Prints
one JSON line: each side's final rows against the centralised run, resends, repeats,
drops, or the error that ended a side.  ``--no-resend`` switches the resends off (the
round must then time out: what the resends repair).  Run it under the test's private ROS
environment (loopback discovery, its own domain id) and a timeout.
"""

import json
import sys
import threading
from dataclasses import replace

import numpy as np
import rclpy
from rclpy.node import Node

from polymatch_ros.core.model import System
from polymatch_ros.core.scenes.scene import load_scene
from polymatch_ros.core.stepping.simulate import (
    choose_numerics,
    drive,
    prepare,
    simulate,
    step_grid,
)
from polymatch_ros.ros import wire
from polymatch_ros.ros.agents import lockstep
from polymatch_ros.ros.agents.agent_base import local_state
from polymatch_ros.ros.wire.intake import DropCounter, Layout

DT, LOST = 0.05, (0, 1, 2)  # the swallowed message: block 0, step 1, stage 2
STALL = 8.0  # s: stall_timeout; resends come after 1 s, even on a loaded machine
NO_RESEND_STALL = 3.0  # s: without resends the round stalls whatever the wait; shorter suffices


def swallow_first(publisher, block, step, stage):
    """Make ``publisher`` drop the first message of (block, step, stage) it is given."""
    send, lost = publisher.publish, []

    def publish(msg):
        head = (msg.sender, msg.step, msg.stage)
        if head == (block, step, stage) and not lost:
            lost.append(head)
            return
        send(msg)

    publisher.publish = publish
    return lost


class Side:
    """One simulated agent process: its node, layout, state and exchange."""

    def __init__(self, scene, the_plan, local, run_id, patience=None):
        self.node = Node(f"agents_{local[0]}_{local[-1]}", namespace="/polymatch")
        self.layout = Layout(scene.model, local, len(local))
        self.system = System(scene.model, self.layout.rows)
        self.state = local_state(scene, self.layout)
        self.exchange = lockstep.LockstepExchange(
            self.node, self.layout, run_id, wire.ROTATION_TOL,
            DropCounter(self.node.get_logger()), scene.t_end,
            patience or lockstep.Patience(STALL))
        self.scene, self.numerics, self.error = scene, the_plan, None

    def run(self, steps):
        prev = 0.0
        try:
            for k, t_next in enumerate(step_grid(self.scene.t_end, DT)[:steps]):
                def answer(request, stage, k=k):
                    return self.exchange.round(k, stage, request, False, 2.0)[0]

                self.state = drive(self.numerics.method, self.system, self.state, t_next - prev,
                                   answer)
                self.state.t = prev = t_next
        except Exception as exc:  # reported, not raised: the other side must end too
            self.error = f"{type(exc).__name__}: {exc}"

    def deviation(self, reference):
        grp, rows = self.scene.model.rotations, self.layout.rows[0]
        got, want = self.state.groups[0], reference.groups[0]
        rot = np.max(np.abs(grp.to_matrices(got.rot) - grp.to_matrices(grp.take(want.rot, rows))))
        return float(max(rot, np.max(np.abs(got.x - want.x[rows]))))


def main(argv):
    scene_path, steps = argv[0], int(argv[1])
    global STALL
    if "--no-resend" in argv:
        lockstep.RESEND_AFTER = float("inf")
        STALL = NO_RESEND_STALL
    rclpy.init()
    scene = load_scene(scene_path)
    the_plan = choose_numerics(scene, "rkmk4", DT, distributed=True)
    scene = prepare(scene, the_plan, distributed=True)
    sides = [Side(scene, the_plan, list(range(4)), 7), Side(scene, the_plan, list(range(4, 8)), 7)]
    lost = swallow_first(sides[0].exchange.pubs[LOST[0]], *LOST)
    for _ in range(400):  # 20 s: both sides matched
        for side in sides:
            side.exchange.spin_once(0.05)
        if all(side.exchange.matched() for side in sides):
            break
    threads = [threading.Thread(target=side.run, args=(steps,)) for side in sides]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    return report(scene, steps, sides, lost=len(lost))


def report(scene, steps, sides, **extra):
    """Print the JSON line of ``sides`` after ``steps`` steps (``extra`` first), end them."""
    t_end = steps * DT
    reference = simulate(replace(scene, t_end=t_end), "rkmk4", DT, samples=[t_end],
                         metrics=False).final
    print(json.dumps({
        **extra,
        "errors": [side.error for side in sides],
        "deviation": [None if side.error else side.deviation(reference) for side in sides],
        "resends": [side.exchange.resends for side in sides],
        "repeats": [side.exchange.repeats for side in sides],
        "drops": [side.exchange.drops.total for side in sides],
    }), flush=True)
    for side in sides:
        side.exchange.destroy()
        side.node.destroy_node()
    rclpy.shutdown()
    return 0

if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
