"""Two lockstep ensembles at a time, over and over, on one machine: do runs survive a shared,
busy machine?  With ``--compare-shared-memory`` every other run uses the shipped loopback
profile without its transport settings (Fast DDS's default transports: shared memory and UDP),
so both transports are measured side by side under the same load.

    python test/support/side_by_side_runs.py --minutes 20 --compare-shared-memory

Each run is ``polymatch run congruent_triangles -k 2 --timeout 120`` (its own domain id, loopback
discovery, bounded by ``timeout``); the logs of failed runs are kept in ``--logs``.  Prints
one line per failed run and, per profile, the runs that passed and failed and the median rate
(rounds/s per agent) of those that passed; ``--parallel 1`` measures the rates alone.
"""

import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from collections import Counter

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SHIPPED = os.path.join(REPO, "polymatch_ros", "ros", "resources", "fastdds_profile.xml")
RATE = re.compile(r"([\d.]+) rounds/s per agent \(mean\)")
TRANSPORT_PARTS = (
    r"\s*<transport_descriptors>.*?</transport_descriptors>",
    r"\s*<userTransports>.*?</userTransports>",
    r"\s*<useBuiltinTransports>.*?</useBuiltinTransports>",
    r"\s*<defaultUnicastLocatorList>.*?</defaultUnicastLocatorList>",
    r"\s*<metatrafficUnicastLocatorList>.*?</metatrafficUnicastLocatorList>",
)


def default_transport_profile(directory):
    """The shipped profile without its transport settings, written into ``directory``."""
    with open(SHIPPED, encoding="utf-8") as fh:
        text = fh.read()
    for part in TRANSPORT_PARTS:
        text = re.sub(part, "", text, flags=re.S)
    path = os.path.join(directory, "default_transports.xml")
    with open(path, "w", encoding="utf-8") as fh:
        fh.write(text)
    return path


def start(profile, number, logs):
    env = dict(os.environ, FASTRTPS_DEFAULT_PROFILES_FILE=profile)
    env.pop("ROS_DOMAIN_ID", None)  # each run reserves its own (--isolated)
    log = open(os.path.join(logs, f"run_{number}.log"), "w", encoding="utf-8")
    log.write(f"profile {profile}\n")
    log.flush()
    proc = subprocess.Popen(
        ["timeout", "-k", "10", "200", sys.executable, "-m", "polymatch_ros.cli", "run",
         "congruent_triangles", "-k", "2", "--timeout", "120", "--isolated"],
        stdout=log, stderr=subprocess.STDOUT, env=env, start_new_session=True,
    )
    return proc, log, time.monotonic()


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=20.0)
    ap.add_argument("--parallel", type=int, default=2)
    ap.add_argument("--compare-shared-memory", action="store_true")
    ap.add_argument("--logs", default=None, help="directory for the logs of failed runs")
    args = ap.parse_args()
    logs = args.logs or tempfile.mkdtemp(prefix="side_by_side_")
    os.makedirs(logs, exist_ok=True)
    profiles = [("udp (shipped)", SHIPPED)]
    if args.compare_shared_memory:
        profiles.append(("default transports", default_transport_profile(logs)))
    end = time.monotonic() + 60.0 * args.minutes
    running, tally, number, rates = {}, Counter(), 0, {}
    while time.monotonic() < end or running:
        try:
            time.sleep(1.0)
        except KeyboardInterrupt:  # start no new run; finish and count the running ones
            end = time.monotonic()
        while time.monotonic() < end and len(running) < args.parallel:
            label, profile = profiles[number % len(profiles)]
            number += 1
            running[number] = (label, *start(profile, number, logs))
        for n, (label, proc, log, t0) in list(running.items()):
            if proc.poll() is None:
                continue
            log.close()
            del running[n]
            good = proc.returncode == 0
            tally[label, good] += 1
            if good:
                path = os.path.join(logs, f"run_{n}.log")
                with open(path, encoding="utf-8") as fh:
                    found = RATE.search(fh.read())
                if found:
                    rates.setdefault(label, []).append(float(found.group(1)))
                os.remove(path)
            else:
                print(f"run {n} ({label}): exit {proc.returncode} after "
                      f"{time.monotonic() - t0:.0f} s, log {logs}/run_{n}.log", flush=True)
    for label, _ in profiles:
        speed = rates.get(label)
        median = f", median {statistics.median(speed):.1f} rounds/s per agent" if speed else ""
        print(f"{label}: {tally[label, True]} passed, {tally[label, False]} failed{median}",
              flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
