"""Run the test suite N times in a row and say whether every run was green.

    python test/support/repeat_tests.py --runs 20 [--logs DIR] [pytest arguments ...]

Each run is `python -m pytest -q test` (the whole suite, as CI runs it), or pytest with the
given arguments (e.g. `-m ros test` for the multi-process ROS tests), in a fresh pytest
process, bounded by a timeout.  The processes' output of every failed test of a ROS world, and
its failure, are kept under DIR/run_<k>/<test>/ (POLYMATCH_KEEP_LOGS), so a rare failure can
be read afterwards.  Prints one line per run, then a `  rerun: <test id>` line for each test a
green run passed only on its rerun (pytest's ``-rR`` summary) and the run's /dev/shm account
where it left something (``shm_account``), and a closing `N passed, N failed` line; the
pytest output of a run that failed, needed a rerun or left something in /dev/shm is kept in
DIR/run_<k>.txt.  Exits 1 if any run failed.
"""

import argparse
import os
import subprocess
import sys
import time

from shm_account import SUMMARY_PREFIX

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def reruns(output):
    """The test ids of pytest's ``RERUN`` summary lines (pytest-rerunfailures, ``-rR``)."""
    return [line.split()[1] for line in output.splitlines()
            if line.startswith("RERUN ") and len(line.split()) > 1]


def shm_left(output):
    """The run's /dev/shm account (``shm_account``) where it left something, else None."""
    for line in output.splitlines():
        if line.startswith(SUMMARY_PREFIX) and not line.endswith(" 0 left by it"):
            return line
    return None


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=10)
    ap.add_argument(
        "--logs", default=os.path.join(os.environ.get("TMPDIR", "/tmp"), "polymatch_ros_runs"))
    ap.add_argument("--timeout", type=float, default=1800.0, help="seconds allowed for one run")
    ap.add_argument("pytest_args", nargs=argparse.REMAINDER)
    args = ap.parse_args(argv)
    selectors = args.pytest_args or ["test"]
    passed = failed = 0
    for k in range(1, args.runs + 1):
        env = dict(os.environ, POLYMATCH_KEEP_LOGS=os.path.join(args.logs, f"run_{k}"))
        t0, proc = time.monotonic(), None
        try:
            proc = subprocess.run(
                [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", *selectors],
                cwd=REPO,
                env=env,
                capture_output=True,
                text=True,
                timeout=args.timeout,
            )
            tail = (proc.stdout.strip().splitlines() or ["(no output)"])[-1]
            ok = proc.returncode == 0
        except subprocess.TimeoutExpired:
            tail, ok = f"timed out after {args.timeout:g} s", False
        passed, failed = passed + ok, failed + (not ok)
        print(
            f"run {k}/{args.runs}: {'green' if ok else 'RED'} in {time.monotonic() - t0:.0f} s: "
            f"{tail}",
            flush=True,
        )
        rerun = reruns(proc.stdout) if proc is not None else []
        for test in rerun:
            print(f"  rerun: {test}", flush=True)
        left = shm_left(proc.stdout) if proc is not None else None
        if left:
            print(f"  {left}", flush=True)
        if not ok or rerun or left:
            os.makedirs(args.logs, exist_ok=True)
            with open(os.path.join(args.logs, f"run_{k}.txt"), "w") as fh:
                fh.write(proc.stdout if proc is not None else tail)
    print(f"runs: {passed} passed, {failed} failed")
    return 0 if failed == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
