"""The ensemble's commands as an agent applies them (``wire.control.AgentControl``): a pause,
resume or reset is applied once per epoch, however often it is delivered."""

import pytest
from builtin_interfaces.msg import Time

from polymatch_interfaces.msg import ControlCommand
from polymatch_ros.ros.wire.control import AgentControl, command_message, parse_command


def _command(text):
    """A ControlCommand built by hand from 'verb [epoch]', as another implementation would:
    the verb's constant from the .msg file, the epoch as a builtin_interfaces/Time."""
    words = text.split()
    msg = ControlCommand(command=getattr(ControlCommand, words[0].upper()))
    if len(words) == 2:
        sec, frac = divmod(float(words[1]), 1.0)
        msg.epoch = Time(sec=int(sec), nanosec=int(round(frac * 1e9)))
    return parse_command(msg)


@pytest.mark.parametrize("verb", ["start", "stop", "pause", "resume", "reset", "received"])
def test_every_verb_is_the_constant_of_the_msg_file_and_reads_back(verb):
    msg = command_message(verb, 1000.25 if verb in ("start", "pause", "resume", "reset") else None)
    assert msg.command == getattr(ControlCommand, verb.upper())
    assert parse_command(msg) == (verb, 1000.25 if msg.epoch.sec else None)


@pytest.mark.parametrize("msg,why", [
    (ControlCommand(command=6), "an unknown command"),
    (ControlCommand(command=255), "an unknown command"),
    (ControlCommand(command=ControlCommand.PAUSE), "a pause without its epoch"),
    (ControlCommand(command=ControlCommand.START, epoch=Time(sec=5, nanosec=10**9)),
     "a malformed epoch"),
])
def test_a_malformed_command_is_refused(msg, why):
    assert parse_command(msg) is None, why


def test_a_reset_delivered_twice_is_applied_once():
    """A realtime agent resets at the first tick past the epoch; the same reset again later (a
    DDS writer's history re-sent to a reader that matched anew) must not send a converged
    ensemble back to its initial state."""
    control = AgentControl("realtime")
    verb, epoch = _command("reset 1000.5")
    assert control.command(verb, epoch)[0]
    assert not control.take_reset(1000.0) and control.take_reset(1000.6)
    accepted, message = control.command(verb, epoch)
    assert accepted and "already applied" in message and control.replays == 1
    assert control.reset_epoch is None and not control.take_reset(1034.0)


def test_a_replayed_pause_does_not_pause_a_resumed_ensemble():
    control = AgentControl("realtime")
    for text in ("pause 10.0", "resume 12.0", "pause 10.0"):
        control.command(*_command(text))
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
