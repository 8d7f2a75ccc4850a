"""Conversions between the grid localizer's messages and plain values."""

from __future__ import annotations

import math

import numpy as np
from geometry_msgs.msg import Pose, PoseWithCovarianceStamped
from nav_msgs.msg import OccupancyGrid

from estimation_nodes.core.geometry import quaternion_from_rpy, yaw_from_quaternion
from estimation_nodes.core.grid.occupancy import OccupancyMap
from estimation_nodes.params.map_files import occupancy_from_message

#: Indices of x, y and yaw in PoseWithCovariance's 6 x 6 covariance (row-major).
POSE_XY_YAW = (0, 1, 5)


def planar_pose(pose: Pose) -> tuple[float, float, float]:
    """(x, y, yaw) of a geometry_msgs Pose."""
    q = pose.orientation
    return pose.position.x, pose.position.y, yaw_from_quaternion(q.x, q.y, q.z, q.w)


def fill_pose(pose: Pose, x: float, y: float, yaw: float) -> None:
    pose.position.x, pose.position.y, pose.position.z = float(x), float(y), 0.0
    (pose.orientation.x, pose.orientation.y, pose.orientation.z,
     pose.orientation.w) = quaternion_from_rpy(0.0, 0.0, yaw)


def covariance_3x3(covariance) -> np.ndarray:
    """The (x, y, yaw) block of a 6 x 6 row-major pose covariance."""
    full = np.asarray(covariance, dtype=np.float64).reshape(6, 6)
    return full[np.ix_(POSE_XY_YAW, POSE_XY_YAW)]


def pose_with_covariance(msg: PoseWithCovarianceStamped, pose: tuple[float, float, float],
                         covariance: np.ndarray) -> PoseWithCovarianceStamped:
    fill_pose(msg.pose.pose, *pose)
    full = np.zeros((6, 6))
    full[np.ix_(POSE_XY_YAW, POSE_XY_YAW)] = covariance
    msg.pose.covariance = full.ravel().tolist()
    return msg


def occupancy_grid(cells: np.ndarray, resolution: float, origin: tuple[float, float],
                   frame_id: str, stamp) -> OccupancyGrid:
    """An OccupancyGrid of int8 ``cells`` (row 0 at ``origin``)."""
    msg = OccupancyGrid()
    msg.header.frame_id = frame_id
    msg.header.stamp = stamp
    msg.info.resolution = float(resolution)
    msg.info.height, msg.info.width = (int(n) for n in cells.shape)
    msg.info.origin.position.x, msg.info.origin.position.y = (float(v) for v in origin)
    msg.info.origin.orientation.w = 1.0
    msg.data = np.ascontiguousarray(cells, dtype=np.int8).ravel().tobytes()
    return msg


def occupancy_of(msg: OccupancyGrid) -> OccupancyMap:
    """The map of an OccupancyGrid message, as the localizer takes it (a MapError names a
    bad field: sizes that do not match, a rotated origin, ...)."""
    info = msg.info
    origin = (info.origin.position.x, info.origin.position.y, planar_pose(info.origin)[2])
    return occupancy_from_message(info.width, info.height, info.resolution, origin, msg.data)


def scan_beams(scan, laser_max_range: float,
               max_beams: int) -> tuple[np.ndarray, np.ndarray, int]:
    """The beams of a LaserScan to score: (ranges, angles) of at most ``max_beams`` valid
    readings, evenly chosen, and how many readings were NaN. Readings at or beyond the
    range (the scan's range_max, or ``laser_max_range`` if that is shorter or the scan's
    is unset; inf is "no return", REP 117) or below range_min (or 0) are not scored; NaN
    ones are counted."""
    range_max = min(scan.range_max, laser_max_range) \
        if math.isfinite(scan.range_max) and scan.range_max > 0 else laser_max_range
    range_min = scan.range_min
    values = np.asarray(scan.ranges, dtype=np.float64)
    angles = scan.angle_min + scan.angle_increment * np.arange(values.size)
    nan = int(np.isnan(values).sum())
    # A negative reading is no return either, whatever range_min a malformed scan gives.
    valid = np.isfinite(values) & (values >= max(range_min, 0.0)) & (values < range_max)
    chosen = np.flatnonzero(valid)
    if chosen.size > max_beams:
        chosen = chosen[np.linspace(0, chosen.size - 1, max_beams).round().astype(int)]
    return values[chosen], angles[chosen], nan


def finite_pose(pose: tuple[float, float, float]) -> bool:
    return all(math.isfinite(v) for v in pose)
