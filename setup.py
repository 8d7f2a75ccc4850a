"""The package's dependencies (the metadata is in pyproject.toml).

They live here rather than in pyproject.toml because two of them are this repository's own
``interfaces/``: ``tf2_msgs/msg/TFMessage`` (``/tf``, ``/tf_static``) and robot_localization's
services ``SetPose`` and ``ToggleFilterProcessing`` (ekf_node's ``set_pose`` and ``toggle``)
are not on PyPI, so pip builds them from their interface definitions, and a pip dependency
on a local directory must be an absolute ``file:`` URL, known only when this file runs. A
ROS install's own packages, on ``PYTHONPATH`` ahead of the environment's, are the ones
imported; a colcon build in a ROS workspace builds neither (colcon does not look for
packages inside a package's folder) and takes tf2_msgs from ROS (package.xml), and
robot_localization's services from ROS where robot_localization is installed.
"""

from pathlib import Path

from setuptools import setup

INTERFACES = Path(__file__).resolve().parent / "interfaces"
#: Directory -> the pip project it builds.
OWN_INTERFACES = {"tf2_msgs": "estimation-nodes-tf2-msgs",
                  "robot_localization": "estimation-nodes-robot-localization-srvs"}

DEPENDENCIES = [
    "ros-jazzy-rclpy",
    "ros-jazzy-common-interfaces",
    "ros-jazzy-rmw-fastrtps-cpp",
    "numpy",
    "pyyaml",
    # Compiled histogram kernels for large worlds (estimation_nodes/core/tiles/compiled.py);
    # imported only for worlds of 65,536 cells or more (in the estimator only with
    # compiled_kernels:=true); without it every size takes numpy's path.
    "numba",
    # Grid localization on a map (grid_localizer, planar_robot): map_server's PGM and PNG
    # images (Pillow, params/map_files.py), and the exact distance transform behind the
    # likelihood field (scipy.ndimage, core/grid/likelihood_field.py).
    "pillow",
    "scipy",
    # ROS 1 bags and rosbag2 recordings (MCAP, sqlite3) without a ROS install: pure Python,
    # maintained, reads both generations of bag with their message definitions
    # (estimation_fuse, tools/fusion/offline.py). Writing our own ROS 1 bag reader would
    # duplicate it.
    "rosbags",
]
for folder, project in OWN_INTERFACES.items():
    if (INTERFACES / folder).is_dir():
        DEPENDENCIES.append(f"{project} @ {(INTERFACES / folder).as_uri()}")

setup(install_requires=DEPENDENCIES)
