"""Environment for every ROS process polymatch starts: loopback discovery, its own domain id.

``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` keeps DDS traffic on loopback; a
fresh ``ROS_DOMAIN_ID`` (reserved through ``domain_coordinator``) keeps
concurrent runs and tests from hearing each other.  Both are left alone when
the user has set them.  The shipped Fast DDS profile shortens discovery.
"""

import contextlib
import os
import re

PROFILE = os.path.join(os.path.dirname(os.path.abspath(__file__)), "resources", "fastdds_profile.xml")


def ros_environment(domain_id=None, base=None):
    """A copy of the environment with discovery on loopback and the given domain id."""
    env = dict(os.environ if base is None else base)
    env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    env.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
    if os.path.isfile(PROFILE):
        env.setdefault("FASTRTPS_DEFAULT_PROFILES_FILE", PROFILE)
    if domain_id is not None:
        env["ROS_DOMAIN_ID"] = str(domain_id)
    env.setdefault("PYTHONUNBUFFERED", "1")
    return env


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
TEARDOWN_MARK = "Timeout ("        # the first line faulthandler writes when the watchdog fires
FINAL_LINE = re.compile(r"^(agent [0-9,]+|monitor): (?!error)")


@contextlib.contextmanager
def teardown_watchdog(seconds=TEARDOWN_SECONDS):
    """Bound the DDS teardown inside the block: past ``seconds``, end the process.

    With Fast DDS 2.14 the last node's teardown can, rarely, spin forever at 100% CPU
    in ``DomainParticipant::set_listener`` (inside ``rmw_destroy_node``), holding the GIL and
    deaf to SIGINT/SIGTERM.  faulthandler's watchdog is a C thread that needs no GIL:
    it writes ``Timeout (...)!`` and the Python stack to stderr and exits with code 1.
    Enter it after the work is done and reported, around the teardown only.
    """
    import faulthandler
    faulthandler.dump_traceback_later(seconds, exit=True)
    try:
        yield
    finally:
        faulthandler.cancel_dump_traceback_later()


def hung_in_teardown(code, lines):
    """True when a child reported its final line, then was ended by the teardown watchdog."""
    return (code == 1 and any(line.startswith(TEARDOWN_MARK) for line in lines)
            and any(FINAL_LINE.match(line) for line in lines))
