"""Environment for every ROS process polymatch starts: loopback discovery, its own domain id.

``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` keeps DDS traffic on loopback; a
fresh ``ROS_DOMAIN_ID`` (reserved through ``domain_coordinator``) keeps
concurrent runs and tests from hearing each other.  Both are left alone when
the user has set them.  The shipped Fast DDS profile shortens discovery.
"""

import contextlib
import os

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
