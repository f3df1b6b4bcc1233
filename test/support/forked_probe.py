"""A stand-in node module for the fork-server tests (test/contract/test_forked_start.py): it
prints what a process can see of how it was started, then exits with the code it is given."""

import os
import sys
import time


def main() -> int:
    with open("/proc/self/cmdline", "rb") as fh:
        cmdline = fh.read().rstrip(b"\0").split(b"\0")
    print("argv", sys.argv[1:])
    print("cmdline", [part.decode() for part in cmdline[1:]])  # after the interpreter's path
    print("env", os.environ.get("PROBE_VALUE"), "PROBE_ABSENT" in os.environ)
    print("own group", os.getpgid(0) == os.getpid())
    print("stdin", sys.stdin.read() if sys.stdin is not None else None)
    print("fd 0 is the null device", os.fstat(0).st_rdev == os.stat(os.devnull).st_rdev)
    sys.stderr.write("to stderr\n")
    code = sys.argv[1] if len(sys.argv) > 1 else "0"
    if code == "wait":
        time.sleep(60)
    if code == "message":
        sys.exit("probe: error: a one-line message")
    return int(code)


if __name__ == "__main__":
    sys.exit(main())
