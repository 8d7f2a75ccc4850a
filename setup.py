"""The package's dependencies (the metadata is in pyproject.toml).

They live here rather than in pyproject.toml because one of them is this repository's own
``interfaces/tf2_msgs``: ``tf2_msgs/msg/TFMessage`` (``/tf``, ``/tf_static``) is not on PyPI,
so pip builds it from its interface definition, and a pip dependency on a local directory
must be an absolute ``file:`` URL, known only when this file runs. A ROS install's own
tf2_msgs, on ``PYTHONPATH`` ahead of the environment's packages, is the one imported; a
colcon build in a ROS workspace takes tf2_msgs from ROS (package.xml) and ignores these.
"""

from pathlib import Path

from setuptools import setup

TF2_MSGS = Path(__file__).resolve().parent / "interfaces" / "tf2_msgs"

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
if TF2_MSGS.is_dir():
    DEPENDENCIES.append(f"estimation-nodes-tf2-msgs @ {TF2_MSGS.as_uri()}")

setup(install_requires=DEPENDENCIES)
