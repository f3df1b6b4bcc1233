"""How long each test held its ROS slot, and how much CPU its processes used meanwhile.

With ``POLYMATCH_SLOT_LOG=FILE`` every slot a test holds (``ros_harness.ros_slot``) appends one
JSON line to FILE: the test, the wall seconds it held the slot and the CPU seconds of the
processes the worker started and reaped meanwhile.  The report sums them (held seconds over
the slots bound the suite's wall time; their CPU share says whether the slots wait or compute)
and lists the tests by held seconds, flagging those that mostly wait (under ``WAITING_SHARE``
of a core)::

    POLYMATCH_SLOT_LOG=/tmp/slots.jsonl python -m pytest -q test
    python test/support/slot_use.py /tmp/slots.jsonl

The CPU of a process that is killed and never reaped by a process the worker reaps is not
counted, nor that of the node processes a run forks (its fork server reaps them, and the system
reaps the fork server once its runner has gone), so a share is a lower bound.
"""

from __future__ import annotations

import contextlib
import json
import os
import resource
import sys
import time

#: a test whose processes use less than this share of a core while it holds its slot mostly
#: waits (on a round timeout, a lease, a resend, start-up)
WAITING_SHARE = 0.5


def _children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


@contextlib.contextmanager
def held():
    """Log the block as one hold of a slot if POLYMATCH_SLOT_LOG is set."""
    path = os.environ.get("POLYMATCH_SLOT_LOG")
    if not path:
        yield
        return
    started, cpu = time.monotonic(), _children_cpu()
    try:
        yield
    finally:
        test = os.environ.get("PYTEST_CURRENT_TEST", "?").rsplit(" ", 1)[0]
        line = {"test": test, "wall": round(time.monotonic() - started, 2),
                "cpu": round(_children_cpu() - cpu, 2)}
        with open(path, "a", encoding="utf-8") as log:
            log.write(json.dumps(line) + "\n")


def report(lines: list[dict]) -> str:
    """The slots' held seconds and CPU share, then the tests by held seconds."""
    wall = sum(line["wall"] for line in lines)
    cpu = sum(line["cpu"] for line in lines)
    out = ["| holds | held s | CPU s | CPU share |", "|---|---|---|---|",
           f"| {len(lines)} | {wall:.0f} | {cpu:.0f} | {cpu / max(wall, 1e-9):.2f} |",
           "", "| held s | CPU share | mostly waits | test |", "|---|---|---|---|"]
    for line in sorted(lines, key=lambda entry: -entry["wall"]):
        share = line["cpu"] / max(line["wall"], 1e-9)
        waits = "yes" if share < WAITING_SHARE else ""
        out.append(f"| {line['wall']:.1f} | {share:.2f} | {waits} | {line['test']} |")
    return "\n".join(out)


def main(argv: list[str]) -> int:
    if len(argv) != 1:
        print("usage: python test/support/slot_use.py LOG", file=sys.stderr)
        return 2
    try:
        with open(argv[0], encoding="utf-8") as log:
            lines = [json.loads(text) for text in log if text.strip()]
    except (OSError, ValueError) as exc:
        print(f"slot_use: error: {argv[0]}: {exc}", file=sys.stderr)
        return 2
    print(report(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
