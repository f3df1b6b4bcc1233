#!/usr/bin/env bash
# Builds the interface package polymatch_interfaces (ament_cmake + rosidl: the run's messages
# and the Match action) against the ROS 2 wheels in .venv, and installs it into .venv itself
# (Python module in site-packages, libraries in .venv/lib, where the wheels' own are found), so
# that .venv/bin/polymatch needs nothing sourced.  Idempotent: builds again only when the
# package's files changed (their hash is kept in .venv).  Needs Debian's cmake and g++.
set -euo pipefail
cd "$(dirname "$0")/.."
venv=$PWD/.venv
stamp=$venv/.polymatch-interfaces.sha256
wanted=$(find polymatch_interfaces scripts/ros_wheels_python.cmake scripts/build-interfaces.sh \
             -type f -print0 | sort -z | xargs -0 cat | sha256sum | cut -d' ' -f1)
if [ "$(cat "$stamp" 2>/dev/null || true)" = "$wanted" ] \
   && "$venv/bin/python" -c "import polymatch_interfaces.msg" 2>/dev/null; then
    echo "interfaces: polymatch_interfaces already built into .venv"
    exit 0
fi
for tool in cmake g++; do
    command -v "$tool" >/dev/null || { echo "interfaces: $tool is missing (Debian: apt-get install cmake g++)" >&2; exit 1; }
done
build=$(mktemp -d)
trap 'rm -rf "$build"' EXIT
includes=$("$venv/bin/python" -c \
    "import sysconfig, numpy; print(sysconfig.get_paths()['include'] + ';' + numpy.get_include())")
export PATH="$venv/bin:$PATH" AMENT_PREFIX_PATH="$venv"
if ! { timeout 600 cmake -S polymatch_interfaces -B "$build" -DCMAKE_BUILD_TYPE=Release \
         -DCMAKE_PREFIX_PATH="$venv" -DCMAKE_INSTALL_PREFIX="$venv" -DBUILD_TESTING=OFF \
         -DPython3_EXECUTABLE="$venv/bin/python" \
         -DCMAKE_PROJECT_INCLUDE="$PWD/scripts/ros_wheels_python.cmake" \
         -DPYTHON_INCLUDE_DIRS="$includes" \
       && timeout 900 cmake --build "$build" -j "$(nproc)" \
       && timeout 300 cmake --install "$build"; } >"$build/log" 2>&1; then
    tail -30 "$build/log" >&2
    echo "interfaces: building polymatch_interfaces failed (the log's end is above)" >&2
    exit 1
fi
echo "$wanted" > "$stamp"
echo "interfaces: built polymatch_interfaces into .venv"
