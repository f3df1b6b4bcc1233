"""Environment for every ROS process polymatch starts: loopback discovery, the run's domain.

``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` keeps DDS traffic on loopback (left alone when
the user has set it).  A run joins the user's ROS graph: the user's ``ROS_DOMAIN_ID``, or ROS's
default domain (0) when none is set, so that a second shell sees it; ``--isolated`` reserves a
fresh domain instead (through ``domain_coordinator``), private to the run: what every test and
benchmark uses, so that concurrent runs never hear each other.  The shipped Fast DDS profile
shortens discovery.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator, Mapping

PROFILE: str = os.path.join(
    os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "resources",
    "fastdds_profile.xml",
)
# Discovery beyond loopback (a user's own ROS_AUTOMATIC_DISCOVERY_RANGE, --discovery): the same
# discovery settings without the loopback-only transport, plus faster repairs on lossy links.
NETWORK_PROFILE: str = os.path.join(os.path.dirname(PROFILE), "fastdds_profile_network.xml")


# Every polymatch process runs over UDP only: Fast DDS 2.14's shared-memory transport can leave
# a peer's port broken, after which messages between two live processes stop for good while
# every other link works (Fast DDS issue #5053): a lockstep round then waits for ever for one
# peer, or the runner never hears the agents' final poses.  Measured with two 8-agent lockstep
# runs side by side, over and over, on 2 busy cores (docs/guide/ros-interface.md): 8 failures
# in 44 runs over shared memory, none over UDP.  Under ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
# FASTDDS_BUILTIN_TRANSPORTS does not remove shared memory (its listener threads and
# /dev/shm segments are there), so the loopback profile (``PROFILE``) names the transport
# itself: UDPv4 on 127.0.0.1 for discovery and data.  rmw_fastrtps still adds a shared-memory
# transport of its own under LOCALHOST; it listens on no port but leaves a segment in /dev/shm
# when its process dies (``shm``).  The variable still selects UDPv4 under the network profile.
# A user's own FASTDDS_BUILTIN_TRANSPORTS and profile file win.
TRANSPORTS: str = "UDPv4"


def ros_environment(domain_id: int | None = None,
                    base: Mapping[str, str] | None = None) -> dict[str, str]:
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
    # each process steps its agents in one thread, on small matrices: OpenBLAS's worker threads
    # (one a core, started at numpy's import) serve none of them, and their start is a share
    # of every process's start-up CPU; a user's own setting wins
    env.setdefault("OPENBLAS_NUM_THREADS", "1")
    return env


#: names the domain its caller reserved (``domain_coordinator``) for itself alone: a run in that
#: domain on loopback has no other ensemble to look for before it starts (``domain_reserved``)
RESERVED_DOMAIN = "POLYMATCH_RESERVED_DOMAIN"


def private_ros_environment(domain_id: int) -> dict[str, str]:
    """``ros_environment`` of a domain reserved for one run (a benchmark, a test): the user's
    own ROS_DOMAIN_ID and ROS_AUTOMATIC_DISCOVERY_RANGE do not carry over, and the domain is
    marked reserved (``RESERVED_DOMAIN``)."""
    user = ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE", RESERVED_DOMAIN)
    base = {k: v for k, v in os.environ.items() if k not in user}
    return dict(ros_environment(domain_id, base=base), **{RESERVED_DOMAIN: str(domain_id)})


def domain_reserved(domain: int, environ: Mapping[str, str] | None = None) -> bool:
    """Whether ``RESERVED_DOMAIN`` names ``domain``: its caller reserved it for this run."""
    return (os.environ if environ is None else environ).get(RESERVED_DOMAIN, "").strip() == \
        str(domain)


#: ROS's domain when ROS_DOMAIN_ID is not set
DEFAULT_DOMAIN = 0
#: the domain ids a ROS_DOMAIN_ID may name (Fast DDS's ports limit them to 0..232)
DOMAIN_IDS = range(233)


def user_domain_id() -> int:
    """The user's ROS_DOMAIN_ID, or ROS's default (0) when it is not set; ValueError (one line)
    if it is not a domain id."""
    text = os.environ.get("ROS_DOMAIN_ID", "").strip()
    if not text:
        return DEFAULT_DOMAIN
    if not text.isdigit() or int(text) not in DOMAIN_IDS:
        raise ValueError(f"ROS_DOMAIN_ID={text!r} is not a domain id (an integer 0..232)")
    return int(text)


@contextlib.contextmanager
def run_domain_id(isolated: bool) -> Iterator[int]:
    """The run's domain: ``user_domain_id()``, or, ``isolated``, one reserved for as long as the
    context lasts (the user's ROS_DOMAIN_ID does not matter)."""
    if not isolated:
        yield user_domain_id()
        return
    from domain_coordinator import domain_id

    with domain_id() as dom:
        yield dom


def describe_domain(domain: int, isolated: bool, discovery: str) -> str:
    """Where a run's processes talk, as its second line says it."""
    if isolated:
        return (f"ROS graph: domain {domain}, private to this run (--isolated): another shell "
                f"does not see it")
    if domain_reserved(domain):
        return (f"ROS graph: domain {domain}, reserved for this run by its caller "
                f"({RESERVED_DOMAIN}), discovery {discovery}")
    whose = ("your ROS_DOMAIN_ID" if os.environ.get("ROS_DOMAIN_ID", "").strip()
             else "ROS's default: ROS_DOMAIN_ID is not set")
    return (f"ROS graph: domain {domain} ({whose}), discovery {discovery}: a second shell with "
            f"the same ROS_DOMAIN_ID sees the run (`polymatch echo /<ensemble>/diameter`); "
            f"--isolated runs in a private domain")
