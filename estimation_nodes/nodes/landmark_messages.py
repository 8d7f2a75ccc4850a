"""Landmark observations as sensor_msgs/PointCloud2: one cloud per camera frame, fields x, y,
z (float32, the landmark in the sensor frame: x = range cos(bearing), y = range
sin(bearing), z = 0) and id (uint32, the landmark)."""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np
from sensor_msgs.msg import PointCloud2, PointField

from estimation_nodes.core.kalman.landmarks import Observation
from estimation_nodes.nodes.grid_messages import covariance_3x3, planar_pose
from estimation_nodes.nodes.stamps import set_stamp

#: PointCloud2 datatypes (sensor_msgs/PointField).
FLOAT32, UINT32 = PointField.FLOAT32, PointField.UINT32


class MalformedCloudError(ValueError):
    """A landmark cloud without the fields this node reads."""


def initial_pose_of(msg) -> tuple[np.ndarray, np.ndarray]:
    """An initialpose's pose (x, y, yaw) and 3 x 3 covariance, as ekf_localizer takes it
    (and estimation_replay judges it); ValueError saying why for one it refuses: not
    finite, or a covariance that is not positive definite."""
    pose = np.array(planar_pose(msg.pose.pose))
    covariance = covariance_3x3(msg.pose.covariance)
    if not (np.isfinite(pose).all() and np.isfinite(covariance).all()):
        raise ValueError("not finite")
    try:
        np.linalg.cholesky(covariance)
    except np.linalg.LinAlgError as error:
        raise ValueError(str(error)) from None
    return pose, covariance


def landmark_points(msg: PointCloud2) -> list[Observation]:
    """The cloud's points as range-bearing observations by landmark id."""
    fields = {f.name: f for f in msg.fields}
    wanted = {"x": FLOAT32, "y": FLOAT32, "id": UINT32}
    for name, datatype in wanted.items():
        if name not in fields or fields[name].datatype != datatype or fields[name].count != 1:
            raise MalformedCloudError(f"expected fields x, y (float32) and id (uint32), got "
                                      f"{sorted(fields)}")
    count = msg.width * msg.height
    if msg.point_step < 12 or len(msg.data) < count * msg.point_step \
            or any(fields[n].offset + 4 > msg.point_step for n in wanted):
        raise MalformedCloudError(f"{count} points of {msg.point_step} bytes need "
                                  f"{count * msg.point_step} bytes, got {len(msg.data)}")
    order = ">" if msg.is_bigendian else "<"
    dtype = np.dtype({"names": ["x", "y", "id"],
                      "formats": [f"{order}f4", f"{order}f4", f"{order}u4"],
                      "offsets": [fields["x"].offset, fields["y"].offset, fields["id"].offset],
                      "itemsize": msg.point_step})
    points = np.frombuffer(bytes(msg.data[:count * msg.point_step]), dtype=dtype)
    x, y = points["x"].astype(np.float64), points["y"].astype(np.float64)
    return [Observation(int(key), float(r), float(b)) for key, r, b in
            zip(points["id"], np.hypot(x, y), np.arctan2(y, x))]



#: One point: x, y, z and id, 16 bytes, little-endian.
POINT = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("id", "<u4")])


def landmark_cloud(stamp_ns: int, frame_id: str,
                   seen: Iterable[tuple[int, float, float]]) -> PointCloud2:
    """A frame's (id, range, bearing) observations as a cloud stamped ``stamp_ns``."""
    seen = list(seen)
    msg = PointCloud2()
    set_stamp(msg.header, stamp_ns, frame_id)
    msg.fields = [PointField(name=name, offset=4 * i, datatype=datatype, count=1)
                  for i, (name, datatype) in enumerate((("x", FLOAT32), ("y", FLOAT32),
                                                         ("z", FLOAT32), ("id", UINT32)))]
    msg.height, msg.width = 1, len(seen)
    msg.is_bigendian, msg.point_step, msg.row_step = False, POINT.itemsize, \
        POINT.itemsize * len(seen)
    msg.is_dense = True
    points = np.zeros(len(seen), dtype=POINT)
    for i, (key, r, b) in enumerate(seen):
        points[i] = (r * math.cos(b), r * math.sin(b), 0.0, key)
    msg.data = points.tobytes()
    return msg
