"""`python -m benchmarks FAMILY [options]` from a checkout (see benchmarks/__init__.py)."""

import sys

from benchmarks import main

if __name__ == "__main__":
    sys.exit(main())
