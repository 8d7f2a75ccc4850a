"""The estimator's outputs as the bytes rclpy would send: CDR, built directly.

Publishing a message object makes rclpy convert every field from Python to C
and then serialize it; for the estimator's small outputs (a Kalman state, its
pose and stamped pose) that cost more than the filter step, and far more than
writing the bytes (docs/benchmarks.md). ``Publisher.publish`` sends ``bytes``
as they are, so these encoders write the serialized form (the encapsulation header
of little-endian plain CDR, then the fields with CDR's alignment, counted
from the end of that header) with the constant part of each layout built
once. tests/node/test_wire.py checks each encoder byte for byte against
rclpy's ``serialize_message`` of the same message, over sizes, labels and
frame ids that exercise every alignment.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from functools import lru_cache
from typing import Any

import numpy as np

from estimation_nodes.core.geometry import quaternion_from_rpy

#: CDR_LE: plain CDR, little-endian, no options.
ENCAPSULATION = b"\x00\x01\x00\x00"
#: Pose axes in the order of PoseWithCovariance's 6 x 6 covariance.
POSE_AXES = ("x", "y", "z", "roll", "pitch", "yaw")

Dimension = tuple[str, int, int]   # label, size, stride: a MultiArrayDimension


def _pad(length: int, alignment: int) -> bytes:
    return b"\x00" * (-length % alignment)


def _cdr_string(body: bytearray, text: str) -> None:
    """A CDR string at the end of ``body``: aligned length with the NUL, bytes, NUL."""
    encoded = text.encode()
    body += _pad(len(body), 4)
    body += struct.pack("<I", len(encoded) + 1) + encoded + b"\x00"


@lru_cache(maxsize=64)
def _multiarray_prefix(dims: tuple[Dimension, ...], count: int) -> bytes:
    """Everything of a Float64MultiArray before its numbers: the layout, the data's length
    and the padding that aligns the numbers to 8 bytes."""
    body = bytearray(struct.pack("<I", len(dims)))
    for label, size, stride in dims:
        _cdr_string(body, label)
        body += _pad(len(body), 4)
        body += struct.pack("<II", size, stride)
    body += _pad(len(body), 4)
    body += struct.pack("<II", 0, count)   # data_offset, data length
    body += _pad(len(body), 8)             # even for no numbers, as Fast CDR does
    return ENCAPSULATION + bytes(body)


def float64_multiarray(values: np.ndarray, dims: tuple[Dimension, ...]) -> bytes:
    """A std_msgs/Float64MultiArray of ``values`` (any shape, read in C order)."""
    contiguous = np.ascontiguousarray(values, dtype="<f8")
    # bytes.join copies the numbers once, straight from the array's buffer.
    return b"".join((_multiarray_prefix(dims, contiguous.size), memoryview(contiguous)))


def vector(values: np.ndarray, label: str) -> bytes:
    """A 1-D array as a Float64MultiArray with one labelled dimension."""
    size = int(np.size(values))
    return float64_multiarray(values, ((label, size, size),))


def state_dims(n: int) -> tuple[Dimension, ...]:
    """The layout of a Kalman state message: an (n + 1) x n array, row 0 x, rows 1..n P."""
    return ((f"row 0: x, rows 1-{n}: P", n + 1, (n + 1) * n), ("state component", n, n))


@lru_cache(maxsize=16)
def _state_prefix(n: int) -> bytes:
    return _multiarray_prefix(state_dims(n), n + n * n)


def state(x: np.ndarray, P: np.ndarray) -> bytes:
    """A Kalman state x (n) and its covariance P (n x n) in one Float64MultiArray, so they
    never come apart (the layout of ``state_dims``)."""
    return b"".join((_state_prefix(x.size),
                     memoryview(np.ascontiguousarray(x, dtype="<f8")),
                     memoryview(np.ascontiguousarray(P, dtype="<f8"))))


@lru_cache(maxsize=32)
def _pose_selection(components: tuple[int, ...], n: int) -> tuple[
        np.ndarray, np.ndarray, np.ndarray, np.ndarray, bool]:
    """Where the chosen parts of x (n) and P (n x n) go among a pose's 43 numbers (3
    position, 4 orientation, then the 6 x 6 covariance row-major): position targets and
    sources in x, covariance targets and sources in P raveled, and whether any component
    is a rotation (else the orientation is the identity)."""
    present = [(axis, c) for axis, c in enumerate(components) if c >= 0]
    position = [(axis, c) for axis, c in present if axis < 3]
    targets = [7 + 6 * row + column for row, _ in present for column, _ in present]
    sources = [ci * n + cj for _, ci in present for _, cj in present]
    return (np.array([axis for axis, _ in position], dtype=np.intp),
            np.array([c for _, c in position], dtype=np.intp),
            np.array(targets, dtype=np.intp), np.array(sources, dtype=np.intp),
            len(position) < len(present))


#: The pose of no rotation: identity quaternion (x, y, z, w) = (0, 0, 0, 1).
_NO_ROTATION = np.zeros(43)
_NO_ROTATION[6] = 1.0


def pose_numbers(x: np.ndarray, P: np.ndarray, components: Sequence[int]) -> np.ndarray:
    """The 43 numbers of a PoseWithCovariance for the state components named by
    ``components`` (indices for x, y, z, roll, pitch, yaw; -1 for none): position,
    orientation as a quaternion, and the matching block of P in the covariance; axes
    without a component are 0."""
    chosen = tuple(components) + (-1,) * (len(POSE_AXES) - len(components))
    position_targets, position_sources, targets, sources, rotated = _pose_selection(
        chosen, x.size)
    numbers = _NO_ROTATION.copy()
    numbers[position_targets] = x[position_sources]
    if rotated:
        angles = [float(x[c]) if c >= 0 else 0.0 for c in chosen[3:]]
        numbers[3:7] = quaternion_from_rpy(*angles)
    numbers[targets] = P.ravel()[sources]
    return numbers


def pose_with_covariance(numbers: np.ndarray) -> bytes:
    """A geometry_msgs/PoseWithCovariance of ``pose_numbers``: all doubles, all aligned."""
    return b"".join((ENCAPSULATION, memoryview(np.ascontiguousarray(numbers, dtype="<f8"))))


@lru_cache(maxsize=16)
def _frame_id_and_padding(frame_id: str) -> bytes:
    """A Header's frame_id after its 8-byte stamp, padded so the pose after it is aligned."""
    body = bytearray(8)
    _cdr_string(body, frame_id)
    body += _pad(len(body), 8)
    return bytes(body[8:])


def pose_with_covariance_stamped(stamp_ns: int, frame_id: str, numbers: np.ndarray) -> bytes:
    """A geometry_msgs/PoseWithCovarianceStamped stamped ``stamp_ns`` (ns since the epoch,
    not negative) in ``frame_id``."""
    seconds, nanoseconds = divmod(stamp_ns, 1_000_000_000)
    return b"".join((ENCAPSULATION, struct.pack("<iI", seconds, nanoseconds),
                     _frame_id_and_padding(frame_id),
                     memoryview(np.ascontiguousarray(numbers, dtype="<f8"))))


# --- inputs -------------------------------------------------------------------------------

class MalformedMessageError(ValueError):
    """Bytes that are not the serialized message they were sent as."""


_U32 = {"<": struct.Struct("<I"), ">": struct.Struct(">I")}


def multiarray_values(data: bytes) -> np.ndarray:
    """The numbers of a serialized std_msgs/Float64MultiArray (read-only; its layout is
    skipped). Either byte order of plain CDR; raises MalformedMessageError for bytes that
    are not such a message."""
    values, _prefix_length = _parse_multiarray(data)
    return values


def _parse_multiarray(data: bytes) -> tuple[np.ndarray, int]:
    """The numbers, and how many bytes come before them."""
    if len(data) < 4 or data[0] != 0 or data[1] not in (0, 1):
        raise MalformedMessageError(
            f"not a plain CDR message (encapsulation {bytes(data[:4]).hex() or 'missing'})")
    order = "<" if data[1] == 1 else ">"
    u32 = _U32[order].unpack_from
    body = memoryview(data)[4:]
    end = len(body)

    def field(offset: int) -> tuple[int, int]:
        offset += -offset % 4
        if offset + 4 > end:
            raise MalformedMessageError("the message ends inside its layout")
        return u32(body, offset)[0], offset + 4

    dims, offset = field(0)
    if dims > end // 12:   # each dimension takes at least 12 bytes
        raise MalformedMessageError(f"{dims} layout dimensions do not fit in {end} bytes")
    for _ in range(dims):
        label_length, offset = field(offset)
        offset += label_length
        _size, offset = field(offset)
        _stride, offset = field(offset)
    _data_offset, offset = field(offset)
    count, offset = field(offset)
    offset += -offset % 8
    # Nothing may follow the numbers but the padding of the whole message to 4 bytes.
    if not 0 <= end - (offset + 8 * count) < 4:
        raise MalformedMessageError(
            f"{count} numbers do not fit the {end - min(offset, end)} bytes after the layout")
    return np.frombuffer(body, dtype=f"{order}f8", count=count, offset=offset), offset + 4


class MultiarrayReader:
    """``multiarray_values`` for the messages of one topic, quicker for a layout seen last.

    A publisher sends its vectors in one layout (labels, sizes, count): everything
    before the numbers is the same bytes each time. A message that starts with the
    bytes of the last one parsed, and has its length, is read without parsing again.
    """

    __slots__ = ("_prefix", "_length", "_dtype")

    def __init__(self) -> None:
        self._prefix, self._length, self._dtype = b"", -1, np.dtype("<f8")

    def __call__(self, data: bytes) -> np.ndarray:
        prefix = self._prefix
        if len(data) == self._length and data.startswith(prefix):
            return np.frombuffer(data, dtype=self._dtype, offset=len(prefix))
        values, prefix_length = _parse_multiarray(data)
        if prefix_length + values.nbytes == len(data):   # no padding after the numbers
            self._prefix, self._length = bytes(data[:prefix_length]), len(data)
            self._dtype = values.dtype
        return values


def from_state_message(msg: Any) -> tuple[np.ndarray, np.ndarray]:
    """x and P back from a received state message (the layout of ``state``)."""
    n = msg.layout.dim[1].size
    values = np.frombuffer(msg.data, dtype=np.float64)
    return values[:n].copy(), values[n:].reshape(n, n).copy()
