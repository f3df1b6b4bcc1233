#!/usr/bin/env bash
# Set up (scripts/setup.sh), the system tools of the multi-host tests
# (install-system-packages.sh test), the colcon workspace of the colcon test (build-colcon.sh;
# the test builds it again, which takes seconds once this is done), then the whole test suite:
# what CI runs (.ci/run).  Extra arguments go to pytest (e.g. -m "not ros and not hosts").
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
bash scripts/install-system-packages.sh test
bash scripts/build-colcon.sh
# each test worker has a core of its own: OpenBLAS's worker threads only add start-up CPU to
# every Python process the tests start (the ROS processes get the same from ros_environment)
export OPENBLAS_NUM_THREADS="${OPENBLAS_NUM_THREADS:-1}"
exec .venv/bin/python -m pytest -q test "$@"
