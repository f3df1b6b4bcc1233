#!/usr/bin/env bash
# Set up (scripts/setup.sh; of the system packages only cmake and g++), then the main demo:
# eight congruent triangles (Figure 1), one ROS process each plus the monitor, in lockstep.
# Extra arguments go to `polymatch run`.  It runs in your ROS graph (your ROS_DOMAIN_ID, or
# ROS's default 0), so a second shell sees it.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
exec .venv/bin/polymatch run config/congruent_triangles.yaml -k 1 "$@"
