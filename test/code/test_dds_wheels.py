"""The Fast DDS the PyPI wheels bring: what docs/guide/hosts-and-graphs.md says of it."""

import pathlib
import sys

import pytest


def _fast_dds_library():
    """The libfastrtps that rmw_fastrtps_cpp loads, found beside this interpreter's ROS."""
    found = sorted(pathlib.Path(sys.prefix, "lib").glob("libfastrtps.so.*"))
    return found[-1] if found else None


def test_the_wheels_fast_dds_has_no_security_plugins():
    """docs/guide/hosts-and-graphs.md, "Security on the wire": the PyPI Fast DDS carries none of
    the DDS Security builtin plugins (authentication PKI-DH, access control, AES-GCM-GMAC) and
    says "security is disabled"; a wheel that brings them makes this fail, and the guide's
    advice wants updating."""
    library = _fast_dds_library()
    if library is None:
        pytest.skip("Fast DDS is not installed as a PyPI wheel here")
    data = library.read_bytes()
    assert b"but security is disabled" in data
    for plugin in (b"PKI-DH", b"Access-Permissions", b"AES-GCM-GMAC"):
        assert plugin not in data, plugin
