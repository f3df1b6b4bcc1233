"""Soak the input contract: `python test/support/soak_inputs.py --examples 5000`.

Runs the property of test_input_contract.py (test/support/input_fuzz.py) over many more mutated
scene files, randomly seeded, and prints the tally of outcomes (what was refused, by key).
"""

import argparse
import sys
import time
from collections import Counter
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from input_fuzz import fuzz  # noqa: E402


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--examples", type=int, default=5000)
    p.add_argument("--top", type=int, default=25, help="outcome lines to print")
    p.add_argument("--derandomize", action="store_true",
                   help="the fixed examples CI runs (test_input_contract.py), not random ones")
    args = p.parse_args()
    stats, slowest = Counter(), {}
    start = time.monotonic()
    try:
        fuzz(args.examples, stats, derandomize=args.derandomize, slowest=slowest)
    finally:
        for key, cpu in sorted(slowest.items()):
            print(f"slowest {key}: {cpu:.2f} s of CPU (the bound: 3 s)")
        total = sum(stats.values())
        print(f"{total} scene files in {time.monotonic() - start:.0f} s; outcomes:")
        for key, n in stats.most_common(args.top):
            print(f"  {n:6d}  {key}")
        rest = sum(n for _, n in stats.most_common()[args.top:])
        if rest:
            print(f"  {rest:6d}  (other keys)")
    print("contract kept: every file ran or was refused in one line with exit 2")


if __name__ == "__main__":
    main()
