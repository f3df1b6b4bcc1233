"""The ensemble's commands as an agent applies them (``nodes.control.AgentControl``): a pause,
resume or reset is applied once per epoch, however often it is delivered."""

from polymatch_ros.ros.nodes.control import AgentControl, parse_command


def test_a_reset_delivered_twice_is_applied_once():
    """A realtime agent resets at the first tick past the epoch; the same reset again later (a
    DDS writer's history re-sent to a reader that matched anew) must not send a converged
    ensemble back to its initial state."""
    control = AgentControl("realtime")
    verb, epoch = parse_command("reset 1000.5")
    assert control.command(verb, epoch)[0]
    assert not control.take_reset(1000.0) and control.take_reset(1000.6)
    accepted, message = control.command(verb, epoch)
    assert accepted and "already applied" in message and control.replays == 1
    assert control.reset_epoch is None and not control.take_reset(1034.0)


def test_a_replayed_pause_does_not_pause_a_resumed_ensemble():
    control = AgentControl("realtime")
    for text in ("pause 10.0", "resume 12.0", "pause 10.0"):
        control.command(*parse_command(text))
    assert not control.paused and control.replays == 1


def test_a_new_epoch_of_the_same_command_is_applied():
    control = AgentControl("realtime")
    control.command("reset", 10.0)
    assert control.take_reset(10.1)
    control.command("reset", 20.0)
    assert control.replays == 0 and control.take_reset(20.1)
    control.command("pause", 21.0)
    control.command("resume", 22.0)
    control.command("pause", 23.0)
    assert control.paused and control.replays == 0
