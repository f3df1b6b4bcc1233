"""Environment for every ROS process polymatch starts: loopback discovery, its own domain id.

``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` keeps DDS traffic on loopback; a
fresh ``ROS_DOMAIN_ID`` (reserved through ``domain_coordinator``) keeps
concurrent runs and tests from hearing each other.  Both are left alone when
the user has set them.  The shipped Fast DDS profile shortens discovery.
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
    return env


def private_ros_environment(domain_id: int) -> dict[str, str]:
    """``ros_environment`` of a domain reserved for one run (a benchmark, a test): the user's
    own ROS_DOMAIN_ID and ROS_AUTOMATIC_DISCOVERY_RANGE do not carry over."""
    user = ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE")
    base = {k: v for k, v in os.environ.items() if k not in user}
    return ros_environment(domain_id, base=base)


@contextlib.contextmanager
def reserved_domain_id() -> Iterator[int]:
    """The user's ROS_DOMAIN_ID if set, else one reserved for as long as the context lasts."""
    if os.environ.get("ROS_DOMAIN_ID"):
        yield int(os.environ["ROS_DOMAIN_ID"])
        return
    from domain_coordinator import domain_id

    with domain_id() as dom:
        yield dom
