"""The estimator's outputs encoded directly equal rclpy's serialization byte for byte.

rclpy leaves CDR's padding bytes as they were in its buffer; we write zeros.
Every other byte must be equal, and the padding must sit where rclpy's does.
"""

import itertools

import numpy as np
import pytest
from geometry_msgs.msg import PoseWithCovariance, PoseWithCovarianceStamped
from rclpy.serialization import deserialize_message, serialize_message
from rclpy.time import Time
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

from estimation_nodes.core.geometry import quaternion_from_rpy
from estimation_nodes.nodes import wire
from tests.node.message_objects import (
    to_multiarray,
    to_pose_with_covariance,
    to_state_message,
)

CACHED = (wire._multiarray_prefix, wire._state_prefix, wire._frame_id_and_padding)


def padding_mask(encode):
    """True where ``encode()`` writes padding: found by encoding again with 0xff padding."""
    plain = encode()
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(wire, "_pad", lambda length, alignment: b"\xff" * (-length % alignment))
        for cache in CACHED:
            cache.cache_clear()
        marked = encode()
    for cache in CACHED:
        cache.cache_clear()
    assert len(plain) == len(marked)
    return np.frombuffer(plain, np.uint8) != np.frombuffer(marked, np.uint8)


def assert_same_cdr(encode, expected: bytes):
    ours = encode()
    assert len(ours) == len(expected)
    differ = np.frombuffer(ours, np.uint8) != np.frombuffer(expected, np.uint8)
    assert not (differ & ~padding_mask(encode)).any(), \
        f"bytes {np.flatnonzero(differ & ~padding_mask(encode)).tolist()} differ"


def random_state(n, seed):
    rng = np.random.default_rng(seed)
    root = rng.normal(size=(n, n))
    return rng.normal(size=n) * 10.0 ** rng.integers(-3, 4), root @ root.T + np.eye(n)


@pytest.mark.parametrize("size", [0, 1, 2, 3, 5, 17, 1000])
@pytest.mark.parametrize("label", ["", "z", "ab", "abc", "cells", "state component"])
def test_vector_equals_rclpy(size, label):
    values = np.random.default_rng(size).normal(size=size)
    assert_same_cdr(lambda: wire.vector(values, label),
                    serialize_message(to_multiarray(values, label)))


@pytest.mark.parametrize("labels", itertools.product(["", "a", "abcd", "abcdefg"], repeat=2))
def test_multiarray_with_two_dimensions_equals_rclpy(labels):
    values = np.arange(6.0).reshape(2, 3)
    dims = ((labels[0], 2, 6), (labels[1], 3, 3))
    msg = Float64MultiArray(data=values.ravel().tolist())
    msg.layout.dim = [MultiArrayDimension(label=label, size=size, stride=stride)
                      for label, size, stride in dims]
    assert_same_cdr(lambda: wire.float64_multiarray(values, dims), serialize_message(msg))


@pytest.mark.parametrize("n", [1, 2, 4, 6, 9, 10])
def test_state_equals_rclpy_and_decodes(n):
    x, P = random_state(n, n)
    assert_same_cdr(lambda: wire.state(x, P), serialize_message(to_state_message(x, P)))
    encoded = wire.state(x, P)
    decoded = deserialize_message(encoded, Float64MultiArray)
    assert [d.label for d in decoded.layout.dim] == [f"row 0: x, rows 1-{n}: P",
                                                      "state component"]
    assert np.array_equal(np.frombuffer(decoded.data)[:n], x)


def test_state_of_a_non_contiguous_covariance():
    x, P = random_state(4, 1)
    assert_same_cdr(lambda: wire.state(x, P.T), serialize_message(to_state_message(x, P.T)))


COMPONENTS = [(0,), (1, 0), (0, 1, -1, -1, -1, 3), (-1, -1, 2), (2, 0, 1, 3, -1, 1), ()]


@pytest.mark.parametrize("components", COMPONENTS)
def test_pose_equals_rclpy(components):
    x, P = random_state(4, len(components))
    # The message function's order and 'x' + 'P' indexing rules: one reference for both.
    expected = to_pose_with_covariance(x, P, components)
    assert_same_cdr(lambda: wire.pose_with_covariance(wire.pose_numbers(x, P, components)),
                    serialize_message(expected))


@pytest.mark.parametrize("frame_id", ["", "m", "map", "odom", "world", "base_link", "x" * 12])
@pytest.mark.parametrize("stamp_ns", [0, 1, 999_999_999, 1_764_000_000_123_456_789])
def test_stamped_pose_equals_rclpy(frame_id, stamp_ns):
    x, P = random_state(4, 3)
    components = (0, 1, -1, -1, -1, 3)
    msg = PoseWithCovarianceStamped()
    msg.header.stamp = Time(nanoseconds=stamp_ns).to_msg()
    msg.header.frame_id = frame_id
    msg.pose = to_pose_with_covariance(x, P, components)
    assert_same_cdr(lambda: wire.pose_with_covariance_stamped(
        stamp_ns, frame_id, wire.pose_numbers(x, P, components)), serialize_message(msg))


@pytest.mark.parametrize("components", COMPONENTS)
def test_pose_numbers_pick_the_components_and_their_covariance_block(components):
    x, P = random_state(4, 5)
    chosen = list(components) + [-1] * (6 - len(components))
    numbers = wire.pose_numbers(x, P, components)
    for axis, c in enumerate(chosen[:3]):
        assert numbers[axis] == (x[c] if c >= 0 else 0.0)
    assert np.allclose(numbers[3:7], quaternion_from_rpy(
        *[x[c] if c >= 0 else 0.0 for c in chosen[3:]]), rtol=0, atol=0)
    covariance = numbers[7:].reshape(6, 6)
    for row, ci in enumerate(chosen):
        for column, cj in enumerate(chosen):
            assert covariance[row, column] == (P[ci, cj] if ci >= 0 and cj >= 0 else 0.0)


def test_pose_message_round_trip():
    x, P = random_state(3, 7)
    decoded = deserialize_message(
        wire.pose_with_covariance(wire.pose_numbers(x, P, (2, 0))), PoseWithCovariance)
    assert (decoded.pose.position.x, decoded.pose.position.y) == (x[2], x[0])
    covariance = np.array(decoded.covariance).reshape(6, 6)
    assert covariance[0, 1] == P[2, 0] and covariance[1, 1] == P[0, 0]
    assert not covariance[2:].any() and not covariance[:, 2:].any()


# --- the vector inputs, read raw ------------------------------------------------------------

def serialized_multiarray(values, labels=()):
    msg = Float64MultiArray(data=list(values))
    msg.layout.dim = [MultiArrayDimension(label=label, size=len(values), stride=len(values))
                      for label in labels]
    msg.layout.data_offset = 3
    return serialize_message(msg)


@pytest.mark.parametrize("size", [0, 1, 2, 3, 4, 9])
@pytest.mark.parametrize("labels", [(), ("z",), ("ab", "abc"), ("", "cells", "u")])
def test_multiarray_values_read_what_rclpy_serialized(size, labels):
    values = np.random.default_rng(size).normal(size=size)
    read = wire.multiarray_values(serialized_multiarray(values, labels))
    assert read.tolist() == values.tolist()


def test_multiarray_values_read_big_endian_cdr():
    # One labelled dimension and two numbers, written by hand in big-endian CDR.
    body = (b"\x00\x00\x00\x01" + b"\x00\x00\x00\x02z\x00" + b"\x00\x00"
            + b"\x00\x00\x00\x02" + b"\x00\x00\x00\x02" + b"\x00\x00\x00\x00"
            + b"\x00\x00\x00\x02" + b"\x00\x00\x00\x00"
            + np.array([1.5, -2.25], dtype=">f8").tobytes())
    assert wire.multiarray_values(b"\x00\x00\x00\x00" + body).tolist() == [1.5, -2.25]


def test_every_truncation_of_a_vector_is_refused_with_a_reason():
    data = serialized_multiarray([1.0, 2.0, 3.0], ("z", "measurement"))
    for length in range(len(data)):
        with pytest.raises(wire.MalformedMessageError):
            wire.multiarray_values(data[:length])


def test_random_bytes_are_refused_or_read_never_crash():
    rng = np.random.default_rng(11)
    template = bytearray(serialized_multiarray([1.0, 2.0], ("z",)))
    for _ in range(3000):
        data = bytearray(template)
        for index in rng.integers(0, len(data), size=rng.integers(1, 4)):
            data[index] = int(rng.integers(0, 256))
        try:
            values = wire.multiarray_values(bytes(data))
        except wire.MalformedMessageError:
            continue
        assert values.dtype.kind == "f" and values.ndim == 1


def test_a_reader_of_one_topic_reads_every_layout_as_the_parser_does():
    """It remembers the last layout: the same one is read without parsing, another one
    (same length, other labels; other counts; bad bytes) is parsed again."""
    rng = np.random.default_rng(12)
    messages = [serialized_multiarray(rng.normal(size=size), labels)
                for size, labels in [(2, ("z",)), (2, ("z",)), (2, ("y",)), (2, ("y",)),
                                     (3, ("y",)), (2, ()), (2, ("z",)), (0, ("z",))]]
    reader = wire.MultiarrayReader()
    for data in messages:
        assert reader(data).tolist() == wire.multiarray_values(data).tolist()
    with pytest.raises(wire.MalformedMessageError):
        reader(messages[-2][:-1])
    data = messages[-2]
    assert reader(data).tolist() == wire.multiarray_values(data).tolist()
