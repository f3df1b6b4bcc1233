#!/usr/bin/env bash
# Builds the repository's two packages with colcon (from PyPI, in .venv) into the workspace
# build/colcon (its build/ and install/ folders), as a ROS 2 user's `colcon build` would: the
# interface package polymatch_interfaces (ament_cmake + rosidl, against the ROS 2 wheels, as
# build-interfaces.sh does) and polymatch_ros (ament_python).  Set-up runs it once; run again it
# rebuilds only what changed (colcon and cmake keep their build folders), so the test of the
# installed executables (test/ros/test_robustness.py) runs it again for seconds.
set -euo pipefail
cd "$(dirname "$0")/.."
venv=$PWD/.venv
ws=$PWD/build/colcon
mkdir -p "$ws"
includes=$("$venv/bin/python" -c \
    "import sysconfig, numpy; print(sysconfig.get_paths()['include'] + ';' + numpy.get_include())")
export PATH="$venv/bin:$PATH" AMENT_PREFIX_PATH="$venv"
cd "$ws"
if ! timeout -k 5 900 "$venv/bin/colcon" build --base-paths "$OLDPWD" "$OLDPWD/polymatch_interfaces" \
       --build-base "$ws/build" --install-base "$ws/install" \
       --cmake-args "-DCMAKE_PREFIX_PATH=$venv" "-DPython3_EXECUTABLE=$venv/bin/python" \
       -DBUILD_TESTING=OFF "-DCMAKE_PROJECT_INCLUDE=$OLDPWD/scripts/ros_wheels_python.cmake" \
       "-DPYTHON_INCLUDE_DIRS=$includes" >"$ws/build.log" 2>&1; then
    tail -30 "$ws/build.log" >&2
    echo "colcon: building the packages failed (the log's end is above; all of it in $ws/build.log)" >&2
    exit 1
fi
echo "colcon: both packages built into build/colcon/install"
