#!/usr/bin/env bash
# Set up (scripts/setup.sh), then the whole test suite: what CI runs (.ci/run).  Extra
# arguments go to pytest (e.g. -m "not ros and not hosts").
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
exec .venv/bin/python -m pytest -q test "$@"
