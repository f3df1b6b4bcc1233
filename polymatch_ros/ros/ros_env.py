"""Environment for every ROS process polymatch starts: loopback discovery, its own domain id.

``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` keeps DDS traffic on loopback; a
fresh ``ROS_DOMAIN_ID`` (reserved through ``domain_coordinator``) keeps
concurrent runs and tests from hearing each other.  Both are left alone when
the user has set them.  The shipped Fast DDS profile shortens discovery.
"""

import contextlib
import faulthandler
import os
import sys

from .exit_timer import native_exit_timer

PROFILE = os.path.join(
    os.path.dirname(os.path.abspath(__file__)), "resources", "fastdds_profile.xml"
)
# Discovery beyond loopback (a user's own ROS_AUTOMATIC_DISCOVERY_RANGE, --discovery): the same
# discovery settings without the loopback-only transport, plus faster repairs on lossy links.
NETWORK_PROFILE = os.path.join(os.path.dirname(PROFILE), "fastdds_profile_network.xml")


# Every polymatch process runs over UDP only: Fast DDS 2.14's shared-memory transport can leave
# a peer's port broken, after which messages between two live processes stop for good while
# every other link works (Fast DDS issue #5053): a lockstep round then waits for ever for one
# peer, or the runner never hears the agents' final poses.  Measured with two 8-agent lockstep
# runs side by side, over and over, on 2 busy cores (notes in README, "Transport"): 8 failures
# in 44 runs over shared memory, none over UDP.  Under ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
# FASTDDS_BUILTIN_TRANSPORTS does not remove shared memory (its listener threads and
# /dev/shm segments are there), so the loopback profile (``PROFILE``) names the transport
# itself: UDPv4 on 127.0.0.1 for discovery and data.  The variable still selects UDPv4 under the
# network profile.  A user's own FASTDDS_BUILTIN_TRANSPORTS and profile file win.
TRANSPORTS = "UDPv4"


def ros_environment(domain_id=None, base=None):
    """A copy of the environment with discovery on loopback, the given domain id, and the
    transports every polymatch process uses (``TRANSPORTS``)."""
    env = dict(os.environ if base is None else base)
    env.setdefault("FASTDDS_BUILTIN_TRANSPORTS", TRANSPORTS)
    env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    env.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
    loopback = env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    profile = PROFILE if loopback else NETWORK_PROFILE
    if os.path.isfile(profile):
        env.setdefault("FASTRTPS_DEFAULT_PROFILES_FILE", profile)
    if domain_id is not None:
        env["ROS_DOMAIN_ID"] = str(domain_id)
    env.setdefault("PYTHONUNBUFFERED", "1")
    return env


def private_ros_environment(domain_id):
    """``ros_environment`` of a domain reserved for one run (a benchmark, a test): the user's
    own ROS_DOMAIN_ID and ROS_AUTOMATIC_DISCOVERY_RANGE do not carry over."""
    user = ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE")
    base = {k: v for k, v in os.environ.items() if k not in user}
    return ros_environment(domain_id, base=base)


@contextlib.contextmanager
def reserved_domain_id():
    """The user's ROS_DOMAIN_ID if set, else one reserved for as long as the context lasts."""
    if os.environ.get("ROS_DOMAIN_ID"):
        yield int(os.environ["ROS_DOMAIN_ID"])
        return
    from domain_coordinator import domain_id

    with domain_id() as dom:
        yield dom


# -- bounded teardown ----------------------------------------------------------------------

TEARDOWN_SECONDS = 10.0
TEARDOWN_MARK = "Timeout ("  # the first line faulthandler writes when the watchdog fires
EXIT_GRACE = 0.5  # between the stack dump and the hard exit


@contextlib.contextmanager
def teardown_watchdog(seconds=TEARDOWN_SECONDS, exit_code=1):
    """Bound the DDS teardown inside the block: past ``seconds``, end the process with
    ``exit_code`` (the code the process had decided on before its teardown).

    With Fast DDS 2.14 the last node's teardown can, rarely, spin forever at 100% CPU
    in ``DomainParticipant::set_listener`` (inside ``rmw_destroy_node``), holding the GIL and
    deaf to SIGINT/SIGTERM, so no Python thread or signal handler can run.  Two watchdogs
    that need no GIL end it: faulthandler's C thread writes ``Timeout (...)!`` and the
    Python stack to stderr; ``EXIT_GRACE`` later a POSIX timer calls ``_exit(exit_code)``
    (``native_exit_timer``), so a run that succeeded still exits 0.  Where no such timer
    can be made, faulthandler ends the process itself, with code 1.
    Enter it after the work is done and reported, around the teardown only.
    """
    timer = native_exit_timer(seconds + EXIT_GRACE, exit_code or 0)
    faulthandler.dump_traceback_later(seconds, exit=timer is None)
    try:
        yield
    finally:
        faulthandler.cancel_dump_traceback_later()
        if timer is not None:
            timer.cancel()


def hung_in_teardown(code, lines):
    """True when a child printed its final run record, then was ended by the teardown watchdog:
    with its own exit code (the native timer), or with faulthandler's 1 where there is none."""
    from .wire import run_records

    return (
        code is not None
        and any(line.startswith(TEARDOWN_MARK) for line in lines)
        and any(rec.finished for rec in run_records(lines))
    )


def end_process(code):
    """End this process now with ``code``, its output flushed.

    Call it after the bounded teardown, at the very end of a ROS process.  It skips the
    interpreter's finalization (leftover rclpy handles, Fast DDS's C++ static destructors and
    thread joins): a process that had printed its final run record and torn down under the
    watchdog was seen to hang there for minutes (twice: a lockstep agent in the tests, one in
    CI), where no watchdog reaches.
    """
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    os._exit(code)
