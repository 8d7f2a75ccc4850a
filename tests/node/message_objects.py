"""The package's messages built as rclpy message objects, as a plain rclpy node would: the
oracle that nodes/wire.py's bytes are checked against, and inputs for node tests."""

from __future__ import annotations

import array
from collections.abc import Sequence

import numpy as np
from geometry_msgs.msg import PoseWithCovariance
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

from estimation_nodes.nodes.wire import pose_numbers, state_dims


def _multiarray(values: np.ndarray, dims: list[MultiArrayDimension]) -> Float64MultiArray:
    """The data goes through the array's buffer into an ``array.array('d')``: no Python
    list of floats is ever built, which matters for large worlds."""
    contiguous = np.ascontiguousarray(values, dtype=np.float64)
    msg = Float64MultiArray()
    msg.layout.dim = dims
    data = array.array("d")
    # A large array is read through a byte view (one copy, 0.6 ms at 1e6 cells);
    # tobytes() would copy twice (1.3 ms) but is quicker for a few cells.
    data.frombytes(memoryview(contiguous).cast("B") if contiguous.size > 512
                   else contiguous.tobytes())
    msg.data = data
    return msg


def to_multiarray(values: np.ndarray, label: str) -> Float64MultiArray:
    """A 1-D array as a Float64MultiArray with one labelled dimension."""
    size = int(np.size(values))
    return _multiarray(values, [MultiArrayDimension(label=label, size=size, stride=size)])


def to_state_message(x: np.ndarray, P: np.ndarray) -> Float64MultiArray:
    """A Kalman state x (n) and its covariance P (n x n) in one message, so they never come
    apart: an (n + 1) x n array whose row 0 is x and rows 1..n are P, as its labels say."""
    return _multiarray(np.concatenate([x, P.ravel()]), [
        MultiArrayDimension(label=label, size=size, stride=stride)
        for label, size, stride in state_dims(x.size)])


def to_pose_with_covariance(
    x: np.ndarray, P: np.ndarray, components: Sequence[int] = (0,),
    msg: PoseWithCovariance | None = None,
) -> PoseWithCovariance:
    """The state components named by ``components`` as a pose with the matching block of P
    (``wire.pose_numbers`` says which), as a message object (``msg`` filled when given)."""
    numbers = pose_numbers(x, P, components)
    msg = PoseWithCovariance() if msg is None else msg
    msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = numbers[:3].tolist()
    (msg.pose.orientation.x, msg.pose.orientation.y, msg.pose.orientation.z,
     msg.pose.orientation.w) = numbers[3:7].tolist()
    msg.covariance = numbers[7:]
    return msg
