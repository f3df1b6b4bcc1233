"""The suite's account of /dev/shm: what Fast DDS files a run left, and during which tests they
appeared (a pytest plugin, loaded by conftest.py).

Every process of the run (the controller, each xdist worker) lists the Fast DDS entries of
/dev/shm (``fastrtps_*``, ``sem.fastrtps_*``) before and after each test and notes the names
that appeared meanwhile; the workers send their notes to the controller when they end
(``workeroutput``).  The controller lists /dev/shm when the session starts and when it ends:
the entries there at the end and not at the start, and no longer held by a live process (the
owner of a segment holds its lock file), are what the run left.  The terminal summary says so
in one line (``SUMMARY_PREFIX``), naming each entry with the tests during which it appeared
(several where tests ran side by side).  Another user's run on the machine can add entries
too, so the account names; it does not fail the run.
"""

from __future__ import annotations

import contextlib
import json
import os

import pytest

from polymatch_ros.ros.supervisor.shm import lock_held

SHM = "/dev/shm"
PREFIXES = ("fastrtps_", "sem.fastrtps_")
LOCK_SUFFIX = "_el"
SUMMARY_PREFIX = "/dev/shm:"
WORKER_KEY = "polymatch_shm_appeared"


def fast_dds_entries() -> set[str]:
    """The names of Fast DDS's entries in /dev/shm now."""
    try:
        return {name for name in os.listdir(SHM) if name.startswith(PREFIXES)}
    except OSError:
        return set()


def held(name: str) -> bool:
    """Whether a live process holds the lock of the segment ``name`` belongs to (a segment and
    its lock file; a port's semaphore goes with its port's segment)."""
    segment = name.removeprefix("sem.").removesuffix("_mutex").removesuffix(LOCK_SUFFIX)
    return lock_held(os.path.join(SHM, segment + LOCK_SUFFIX))


class ShmAccount:
    """One process's notes: test id -> the entries that appeared while it ran."""

    def __init__(self, config: pytest.Config) -> None:
        self.config = config
        self.at_start = fast_dds_entries()
        self.appeared: dict[str, list[str]] = {}

    @pytest.hookimpl(wrapper=True)
    def pytest_runtest_protocol(self, item: pytest.Item, nextitem: pytest.Item | None):
        before = fast_dds_entries()
        try:
            return (yield)
        finally:
            new = sorted(fast_dds_entries() - before)
            if new:
                self.appeared.setdefault(item.nodeid, []).extend(new)

    def pytest_sessionfinish(self, session: pytest.Session) -> None:
        workeroutput = getattr(self.config, "workeroutput", None)
        if workeroutput is not None:
            workeroutput[WORKER_KEY] = json.dumps(self.appeared)

    @pytest.hookimpl(optionalhook=True)
    def pytest_testnodedown(self, node, error) -> None:
        with contextlib.suppress(AttributeError, KeyError, ValueError):
            for test, names in json.loads(node.workeroutput[WORKER_KEY]).items():
                self.appeared.setdefault(test, []).extend(names)

    def left(self) -> dict[str, list[str]]:
        """Each entry the run left (``fast_dds_entries`` now, not at the start, not held) ->
        the tests during which it appeared."""
        left = sorted(n for n in fast_dds_entries() - self.at_start if not held(n))
        return {name: sorted(t for t, names in self.appeared.items() if name in names)
                for name in left}

    def summary(self) -> str:
        left = self.left()
        text = (f"{SUMMARY_PREFIX} {len(self.at_start)} Fast DDS entries when the run began, "
                f"{len(left)} left by it")
        return text + "".join(f"; {name} (appeared during: {', '.join(tests) or 'no test'})"
                              for name, tests in left.items())

    def pytest_terminal_summary(self, terminalreporter) -> None:
        if getattr(self.config, "workeroutput", None) is None:
            terminalreporter.write_line(self.summary())


def register(config: pytest.Config) -> None:
    """Account for /dev/shm in this pytest process (from conftest.py's ``pytest_configure``)."""
    config.pluginmanager.register(ShmAccount(config), "polymatch_shm_account")
