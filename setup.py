"""ament_python package setup: `colcon build` (ROS from apt) or `pip install .` (ROS from PyPI)."""

import os
import sys
from glob import glob

from setuptools import find_packages, setup

package_name = "polymatch_ros"

# The node executables `ros2 run polymatch_ros agent|monitor|robot|recorder` finds in
# lib/polymatch_ros (setup.cfg's script_dir): colcon's ament_python build runs setup.py's own
# commands (egg_info, build, install or develop).  pip builds a wheel (PEP 517: dist_info,
# bdist_wheel, editable_wheel), whose scripts land on the user's PATH: there only `polymatch`
# goes, and the nodes are `polymatch agent|monitor|robot` (the recorder: `polymatch record`).
NODE_SCRIPTS = [
    "agent = polymatch_ros.ros.nodes.agent:main",
    "monitor = polymatch_ros.ros.nodes.monitor:main",
    "robot = polymatch_ros.ros.nodes.robot:main",
    "recorder = polymatch_ros.ros.nodes.recorder:main",
]
BUILDING_A_WHEEL = bool({"dist_info", "bdist_wheel", "editable_wheel"} & set(sys.argv))

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(include=["polymatch_ros", "polymatch_ros.*"]),
    package_data={package_name: ["ros/resources/*.xml"]},
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        (os.path.join("share", package_name, "config"), glob("config/*.yaml")),
        (os.path.join("share", package_name, "config", "extremes"),
         glob("config/extremes/*.yaml")),
        (os.path.join("share", package_name, "config", "params"), glob("config/params/*.yaml")),
    ],
    install_requires=["setuptools", "numpy", "scipy", "pyyaml", "mcap", "mcap-ros2-support"],
    extras_require={"plot": ["matplotlib"], "test": ["pytest"]},
    zip_safe=True,
    maintainer="polymatch maintainers",
    maintainer_email="maintainers@polymatch.dev",
    description="Shape matching of polytopes along rigid-body motions as a ROS 2 node set",
    license="Apache-2.0",
    tests_require=["pytest"],
    entry_points={
        "console_scripts": ["polymatch = polymatch_ros.cli:main"]
        + ([] if BUILDING_A_WHEEL else NODE_SCRIPTS),
    },
)
