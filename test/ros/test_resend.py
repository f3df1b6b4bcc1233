"""A lockstep stage message lost for good: the round re-sends and the run stays exact.

RELIABLE delivery repairs a lost datagram, but not a sample sent before a starved peer was
matched anew (its DDS lease ran out; the stage topics are VOLATILE), and then every process
waits for a present peer for ever.  ``test/support/lost_stage.py`` drives two exchanges of the
Fig. 1 scene (agents 0-3 and 4-7, as two agent processes) and swallows one message of agents 0-3
(their block's).
"""

import json
import os

from ros_harness import PY, REPO, needs_ros, scene_path

pytestmark = needs_ros

SCRIPT = os.path.join(REPO, "test", "support", "lost_stage.py")
STEPS = 3  # 12 rounds of rkmk4; the message of step 1, stage 2 is lost


def _run(ros, *extra, script=SCRIPT):
    proc = ros.start([PY, script, scene_path("congruent_triangles"), str(STEPS), *extra],
                     timeout=60)
    assert ros.wait(proc, 70) == 0, ros.output(proc)
    lines = [line for line in ros.output(proc).splitlines() if line.startswith("{")]
    assert lines, ros.output(proc)
    return json.loads(lines[-1])


def test_a_lost_stage_message_is_resent_and_lockstep_equals_centralised_theorem_4_2(ros):
    got = _run(ros)
    assert got["lost"] == 1 and got["errors"] == [None, None], got
    assert max(got["deviation"]) <= 1e-12, got       # still the centralised trajectory
    assert got["resends"][0] >= 1, got                # agent 0's side re-sent its rounds
    assert got["drops"] == [0, 0], got                # a resend is not a dropped message


def test_without_resends_the_same_loss_stalls_the_round(ros):
    got = _run(ros, "--no-resend")
    assert got["lost"] == 1, got
    assert any(e and "present but silent" in e for e in got["errors"]), got


REPLAY = os.path.join(REPO, "test", "support", "replayed_step.py")


def test_a_process_restarted_after_its_last_step_replays_it_with_a_holding_peer_theorem_4_2(ros):
    """A lockstep process that died after its last step, before the runner had its final
    state, is restarted and resumes at that step; its peer, holding its final poses, answers
    the replay with its kept rounds, and the replayed step ends where the centralised run
    does."""
    got = _run(ros, script=REPLAY)
    assert got["errors"] == [None, None], got
    assert got["deviation"][0] <= 1e-12, got  # the replayed step: still the centralised run
    assert got["resends"][1] >= 1 and got["repeats"][1] >= 1, got  # the holder answered
    assert got["drops"] == [0, 0], got


def test_a_holding_peer_that_does_not_answer_stalls_the_replay(ros):
    got = _run(ros, "--no-answer", script=REPLAY)
    assert got["errors"][0] and "present but silent" in got["errors"][0], got
