"""A lockstep process restarted after its last step replays it against a peer that holds.

    python test/support/replayed_step.py SCENE STEPS [--no-answer]

Agents 0-3 and 4-7 of SCENE are two ``LockstepExchange`` sides (``lost_stage.Side``), run
under the restart policy (peers restart; a step and two rounds kept).  Both run STEPS rkmk4
steps; side 0 keeps what its checkpoint would hold at the start of the last step (its state,
its kept messages).  Then side 0 dies (its node and exchange destroyed) and a new side 0
resumes at that step, as a process restarted after its run does, while side 1 holds its
final poses (``LockstepAgent.settle``): it answers the replay (``answer_replays``), and the
new side 0 ends the step again.  Prints ``lost_stage``'s JSON line for [new side 0, side 1]:
final rows against the centralised run, resends, repeats, drops, errors.  ``--no-answer``
makes the holder only spin (the replay must then stall).  Run it under the test's private
ROS environment (loopback discovery, its own domain id) and a timeout.
"""

import copy
import sys
import threading

import rclpy
from lost_stage import DT, Side, report

from polymatch_ros.core.scenes.scene import load_scene
from polymatch_ros.core.stepping.simulate import choose_numerics, drive, prepare, step_grid
from polymatch_ros.ros.agents import lockstep

STALL = 8.0  # s: a replay not answered stalls this long, then fails
NO_ANSWER_STALL = 3.0  # s: a holder that never answers stalls the replay whatever the wait


def patience(the_plan):
    """What ``LockstepAgent`` sets under ``--on-failure restart``."""
    return lockstep.Patience(STALL, True, the_plan.method.info.rounds + 2)


def run_steps(side, first, last, kept=None):
    """Steps ``first`` .. ``last - 1`` of ``side``; ``kept`` gets the checkpoint of the last."""
    grid = step_grid(side.scene.t_end, DT)
    prev = float(grid[first - 1]) if first else 0.0
    try:
        for k in range(first, last):
            if kept is not None and k == last - 1:
                kept.append((copy.deepcopy(side.state), side.exchange.links.snapshot()))

            def answer(request, stage, k=k):
                return side.exchange.round(k, stage, request, False, 2.0)[0]

            side.state = drive(side.numerics.method, side.system, side.state, grid[k] - prev,
                               answer)
            side.state.t = prev = float(grid[k])
    except Exception as exc:  # reported, not raised: the holder must end too
        side.error = f"{type(exc).__name__}: {exc}"


def match(sides):
    for _ in range(400):  # 20 s: both sides matched
        for side in sides:
            side.exchange.spin_once(0.05)
        if all(side.exchange.matched() for side in sides):
            return


def main(argv):
    global STALL
    scene_path, steps = argv[0], int(argv[1])
    answering = "--no-answer" not in argv
    if not answering:
        STALL = NO_ANSWER_STALL
    rclpy.init()
    scene = load_scene(scene_path)
    the_plan = choose_numerics(scene, "rkmk4", DT, distributed=True)
    scene = prepare(scene, the_plan, distributed=True)
    sides = [Side(scene, the_plan, list(range(4)), 7, patience(the_plan)),
             Side(scene, the_plan, list(range(4, 8)), 7, patience(the_plan))]
    match(sides)
    kept = []
    threads = [threading.Thread(target=run_steps, args=(sides[0], 0, steps, kept)),
               threading.Thread(target=run_steps, args=(sides[1], 0, steps))]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    sides[0].exchange.destroy()  # side 0 dies after its last step
    sides[0].node.destroy_node()
    state, sent = kept[0]
    new = Side(scene, the_plan, list(range(4)), 7, patience(the_plan))
    new.state = state
    new.exchange.resume_at(steps - 1)
    new.exchange.links.restore(sent)
    holder, released = sides[1], threading.Event()

    def hold():
        while not released.is_set():
            if answering:
                holder.exchange.answer_replays(0.02)
            else:
                holder.exchange.spin_once(0.02)

    holding = threading.Thread(target=hold)
    holding.start()
    match([new])
    run_steps(new, steps - 1, steps)
    released.set()
    holding.join()
    return report(scene, steps, [new, holder])


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
