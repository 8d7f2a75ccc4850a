"""The transform tree (core/transforms): compositions by hand and against scipy's rotations,
tf2's interpolation and lookup rules, refusals that leave the tree as it was, and the CARMEN
logs' own poses put through it."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation, Slerp

from estimation_nodes.core.errors import InvalidInputError
from estimation_nodes.core.geometry import compose, relative
from estimation_nodes.core.transforms.buffer import (
    Extrapolation, NotConnected, TransformBuffer, TransformRejected, UnknownFrame)
from estimation_nodes.core.transforms.rigid import Transform, interpolate

S = 1_000_000_000
SHARED = Path(__file__).resolve().parents[3] / "shared" / "data"

angles = st.floats(-math.pi, math.pi)
lengths = st.floats(-50.0, 50.0)


def random_transform(rng: np.random.Generator) -> Transform:
    q = Rotation.random(random_state=rng).as_quat()
    return Transform(tuple(rng.uniform(-5, 5, 3)), tuple(q))


def as_matrix(t: Transform) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = Rotation.from_quat(t.rotation).as_matrix()
    m[:3, 3] = t.translation
    return m


def test_composition_by_hand():
    # The laser 0.25 m ahead of base_link; base_link at (1, 2) facing +y in odom.
    odom_base = Transform.planar(1.0, 2.0, math.pi / 2)
    base_laser = Transform((0.25, 0.0, 0.1))
    odom_laser = odom_base * base_laser
    np.testing.assert_allclose(odom_laser.translation, (1.0, 2.25, 0.1), atol=1e-15)
    np.testing.assert_allclose(odom_laser.as_planar()[2], math.pi / 2)
    np.testing.assert_allclose(odom_laser.inverse().apply((1.0, 2.25, 0.1)), (0, 0, 0),
                               atol=1e-15)


def test_composition_inverse_and_application_equal_scipys_matrices():
    rng = np.random.default_rng(3)
    for _ in range(50):
        a, b = random_transform(rng), random_transform(rng)
        np.testing.assert_allclose(as_matrix(a * b), as_matrix(a) @ as_matrix(b), atol=1e-12)
        np.testing.assert_allclose(as_matrix(a.inverse()), np.linalg.inv(as_matrix(a)),
                                   atol=1e-12)
        point = rng.uniform(-3, 3, 3)
        np.testing.assert_allclose(a.apply(tuple(point)), (as_matrix(a) @ [*point, 1])[:3],
                                   atol=1e-12)


def test_interpolation_is_linear_in_translation_and_scipys_slerp_in_rotation():
    rng = np.random.default_rng(4)
    for ratio in (0.0, 0.1, 0.5, 0.93, 1.0):
        a, b = random_transform(rng), random_transform(rng)
        mid = interpolate(a, b, ratio)
        np.testing.assert_allclose(
            mid.translation, np.add(a.translation, ratio * np.subtract(b.translation,
                                                                       a.translation)))
        expected = Slerp([0, 1], Rotation.from_quat([a.rotation, b.rotation]))(ratio)
        got = Rotation.from_quat(mid.rotation)
        assert (expected.inv() * got).magnitude() < 1e-9


@settings(max_examples=200, deadline=None)
@given(a=st.tuples(lengths, lengths, angles), b=st.tuples(lengths, lengths, angles))
def test_planar_transforms_compose_as_planar_poses(a, b):
    got = (Transform.planar(*a) * Transform.planar(*b)).as_planar()
    expected = compose(a, b)
    np.testing.assert_allclose(got[:2], expected[:2], atol=1e-9)
    assert abs(math.remainder(got[2] - expected[2], 2 * math.pi)) < 1e-9


def test_checked_refuses_non_finite_and_non_unit_rotations_and_normalizes_rounding():
    with pytest.raises(InvalidInputError, match="non-finite"):
        Transform.checked((0, math.nan, 0), (0, 0, 0, 1))
    with pytest.raises(InvalidInputError, match="not a unit quaternion"):
        Transform.checked((0, 0, 0), (0, 0, 0, 0))
    t = Transform.checked((0, 0, 0), (0, 0, 0, 1.01))
    assert t.rotation == (0.0, 0.0, 0.0, 1.0)


def tree() -> TransformBuffer:
    """map -> odom (static here), odom -> base_link at 1 s and 2 s, base_link -> laser."""
    buffer = TransformBuffer()
    buffer.set_transform("map", "odom", 0, Transform.planar(10.0, 0.0, 0.0), static=True)
    buffer.set_transform("odom", "base_link", 1 * S, Transform.planar(0.0, 0.0, 0.0))
    buffer.set_transform("odom", "base_link", 2 * S, Transform.planar(2.0, 0.0, math.pi / 2))
    buffer.set_transform("base_link", "laser", 0, Transform((0.25, 0.0, 0.0)), static=True)
    return buffer


def test_a_lookup_between_samples_interpolates_and_composes_the_way():
    buffer = tree()
    got = buffer.lookup("map", "laser", int(1.5 * S)).as_planar()
    # base_link half way: (1, 0), yaw pi/4; the laser 0.25 m ahead along that heading.
    expected = compose((11.0, 0.0, math.pi / 4), (0.25, 0.0, 0.0))
    np.testing.assert_allclose(got, expected, atol=1e-12)
    # The other way round is the inverse.
    back = buffer.lookup("laser", "map", int(1.5 * S)).as_planar()
    np.testing.assert_allclose(back, relative(expected, (0.0, 0.0, 0.0)), atol=1e-12)


def test_time_zero_is_the_latest_time_the_whole_way_holds():
    buffer = tree()
    np.testing.assert_allclose(buffer.lookup("map", "base_link").as_planar(),
                               (12.0, 0.0, math.pi / 2), atol=1e-12)
    # Static only: any time.
    assert buffer.lookup("base_link", "laser", 123 * S).translation == (0.25, 0.0, 0.0)


def test_extrapolation_names_the_edge_and_the_times_held():
    buffer = tree()
    with pytest.raises(Extrapolation, match=r"odom -> base_link at 2\.500 s: extrapolation "
                                            r"into the future \(held 1\.000 to 2\.000 s\)"):
        buffer.lookup("map", "laser", int(2.5 * S))
    with pytest.raises(Extrapolation, match="into the past"):
        buffer.lookup("odom", "base_link", int(0.5 * S))


def test_unknown_and_unconnected_frames_are_named():
    buffer = tree()
    with pytest.raises(UnknownFrame, match="frame 'imu_link' does not exist"):
        buffer.lookup("base_link", "imu_link")
    buffer.set_transform("world", "gps", 0, Transform(), static=True)
    with pytest.raises(NotConnected, match="'gps' and 'laser' are not connected"):
        buffer.lookup("laser", "gps")


@pytest.mark.parametrize("parent, child, static, reason", [
    ("laser", "map", False, "loop"),           # map is the laser's root
    ("world", "odom", True, "second_parent"),  # odom's parent is map
    ("odom", "odom", False, "self_parent"),
    ("", "odom", False, "empty_frame"),
    ("base_link", "laser", False, "static_and_dynamic"),
])
def test_a_broken_tree_is_refused_and_leaves_the_tree_as_it_was(parent, child, static,
                                                                 reason):
    buffer = tree()
    before = buffer.lookup("map", "laser", int(1.5 * S))
    with pytest.raises(TransformRejected) as refused:
        buffer.set_transform(parent, child, 3 * S, Transform(), static=static)
    assert refused.value.reason == reason
    assert buffer.lookup("map", "laser", int(1.5 * S)) == before
    assert buffer.parent_of("odom") == "map"


def test_a_changed_static_transform_is_refused_and_the_same_one_again_taken():
    buffer = tree()
    buffer.set_transform("base_link", "laser", 5 * S, Transform((0.25, 0.0, 0.0)), static=True)
    with pytest.raises(TransformRejected) as refused:
        buffer.set_transform("base_link", "laser", 0, Transform((0.5, 0.0, 0.0)), static=True)
    assert refused.value.reason == "static_changed"
    assert buffer.lookup("base_link", "laser").translation == (0.25, 0.0, 0.0)


def test_repeated_old_and_future_stamps_are_refused():
    buffer = tree()
    with pytest.raises(TransformRejected) as repeated:
        buffer.set_transform("odom", "base_link", 2 * S, Transform.planar(9.0, 9.0, 0.0))
    assert repeated.value.reason == "repeated_stamp"
    assert buffer.lookup("odom", "base_link", 2 * S).as_planar()[0] == 2.0
    buffer.set_transform("odom", "base_link", 20 * S, Transform.planar(3.0, 0.0, 0.0))
    with pytest.raises(TransformRejected) as old:
        buffer.set_transform("odom", "base_link", 5 * S, Transform())
    assert old.value.reason == "too_old"
    with pytest.raises(TransformRejected) as future:
        buffer.set_transform("odom", "base_link", 30 * S, Transform(), now_ns=21 * S,
                             future_tolerance_ns=S)
    assert future.value.reason == "future"
    # The cache keeps 10 s: the samples at 1 and 2 s are gone.
    with pytest.raises(Extrapolation):
        buffer.lookup("odom", "base_link", int(1.5 * S))


def test_clear_forgets_dynamic_transforms_and_keeps_static_ones():
    buffer = tree()
    buffer.clear()
    assert buffer.parent_of("base_link") is None
    assert buffer.lookup("map", "odom").translation == (10.0, 0.0, 0.0)
    buffer.set_transform("odom", "base_link", 1 * S, Transform.planar(1.0, 0.0, 0.0))
    np.testing.assert_allclose(buffer.lookup("map", "base_link", S).translation[0], 11.0)


@pytest.mark.skipif(not (SHARED / "carmen").is_dir(), reason=f"no CARMEN logs at {SHARED}")
def test_the_intel_logs_poses_through_the_tree():
    """odom -> base_link from every odometry line: at each scan's time the tree gives the
    planar interpolation of the odometry lines around it; map -> odom as a localizer
    publishes it (the corrected pose composed with the odometry's inverse) brings
    map -> base_link, through the tree, back to the corrected pose."""
    from estimation_nodes.tools.importers import carmen

    log = carmen.read_log(SHARED / "carmen" / "intel-corrected.log.gz")
    buffer = TransformBuffer(cache_time_ns=3600 * S)
    odometry = {}
    for sample in log.odometry:
        stamp = int(sample.t * S)
        try:
            buffer.set_transform("odom", "base_link", stamp, Transform.planar(*sample.pose))
            odometry[stamp] = sample.pose
        except TransformRejected as refused:
            assert refused.reason == "repeated_stamp"
    stamps = sorted(odometry)
    corrected = {}
    for scan in log.scans:
        t = int(scan.t * S)
        i = int(np.searchsorted(stamps, t))
        if i == 0 or i == len(stamps) or t in corrected:
            continue
        (ax, ay, ayaw), (bx, by, byaw) = odometry[stamps[i - 1]], odometry[stamps[i]]
        r = (t - stamps[i - 1]) / (stamps[i] - stamps[i - 1])
        expected = (ax + r * (bx - ax), ay + r * (by - ay),
                    ayaw + r * math.remainder(byaw - ayaw, 2 * math.pi))
        odom_base = buffer.lookup("odom", "base_link", t)
        got = odom_base.as_planar()
        np.testing.assert_allclose(got[:2], expected[:2], atol=1e-9)
        assert abs(math.remainder(got[2] - expected[2], 2 * math.pi)) < 1e-9
        buffer.set_transform("map", "odom", t, Transform.planar(*scan.pose) * odom_base.inverse())
        corrected[t] = scan.pose
    assert len(corrected) > 0.9 * len(log.scans)
    for t, pose in corrected.items():
        got = buffer.lookup("map", "base_link", t).as_planar()
        np.testing.assert_allclose(got[:2], pose[:2], atol=1e-9)
        assert abs(math.remainder(got[2] - pose[2], 2 * math.pi)) < 1e-9
