"""The 15-state fusion core: its motion model, steps and inputs against direct computations."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from estimation_nodes.core.fusion import inputs, motion, state, steps
from estimation_nodes.core.transforms import rigid
from estimation_nodes.core.fusion.filter import FusionFilter, FusionSettings
from estimation_nodes.core.fusion.steps import Measurement
from estimation_nodes.params.fusion import FusionConfigError, fusion_config

RNG = np.random.default_rng(7)


def random_state() -> np.ndarray:
    x = RNG.normal(size=15)
    x[state.PITCH] = RNG.uniform(-1.0, 1.0)
    return x


@pytest.mark.parametrize("seed", range(5))
def test_the_jacobian_is_the_derivative_of_the_motion(seed):
    x, dt, eps = random_state(), 0.05, 1e-6

    def move(v):
        return motion.transfer(v, dt) @ v

    numeric = np.column_stack([(move(x + eps * e) - move(x - eps * e)) / (2 * eps)
                               for e in np.eye(15)])
    np.testing.assert_allclose(motion.jacobian(x, dt), numeric, atol=1e-7)


def test_the_motion_moves_the_pose_by_the_rotated_twist():
    x = np.zeros(15)
    x[state.YAW] = math.pi / 2
    x[state.VX] = 2.0
    x[state.AX] = 1.0
    moved = motion.transfer(x, 0.5) @ x
    # Facing +y: 2 m/s for 0.5 s plus 1/2 * 1 * 0.25 along y, and vx grows by a dt.
    np.testing.assert_allclose(moved[[state.X, state.Y, state.VX]], [0.0, 1.125, 2.5],
                               atol=1e-12)


@pytest.mark.parametrize("rpy", [(0.1, -0.4, 2.5), (-3.0, 1.2, -0.3), (0.0, 0.0, 0.0)])
def test_rpy_round_trips_through_the_rotation_and_the_quaternion(rpy):
    rotation = state.rotation_from_rpy(*rpy)
    np.testing.assert_allclose(state.rpy_from_rotation(rotation), rpy, atol=1e-12)
    q = state.quaternion_from_rpy(*rpy)
    np.testing.assert_allclose(state.rotation_from_quaternion(*q), rotation, atol=1e-12)


def test_ekf_correct_is_the_joseph_form_of_the_direct_computation():
    x = random_state()
    a = RNG.normal(size=(15, 15))
    p = a @ a.T + np.eye(15)
    z = np.zeros(15)
    z[[6, 11]] = [1.5, -0.2]
    r = np.diag(np.full(15, 0.04))
    measurement = Measurement(0, z, r, (6, 11))
    x_new, p_new = steps.ekf_correct(x, p, measurement)
    h = np.eye(15)[[6, 11]]
    k = p @ h.T @ np.linalg.inv(h @ p @ h.T + r[np.ix_([6, 11], [6, 11])])
    np.testing.assert_allclose(x_new, state.wrap_state_angles(x + k @ (z[[6, 11]] - h @ x)),
                               atol=1e-10)
    np.testing.assert_allclose(p_new, (np.eye(15) - k @ h) @ p, atol=1e-9)


def test_a_measurement_beyond_its_threshold_is_rejected_and_changes_nothing():
    fusion = FusionFilter(FusionSettings())
    z = np.zeros(15)
    fusion.process(Measurement(0, z, np.eye(15) * 0.01, (6,), source="odom0_twist"))
    far = z.copy()
    far[6] = 100.0
    x_before = fusion.x.copy()
    assert not fusion.process(Measurement(0, far, np.eye(15) * 0.01, (6,), 3.0, "odom0_twist"))
    np.testing.assert_array_equal(fusion.x, x_before)
    assert fusion.counts.rejected == {"odom0_twist": 1}


@pytest.mark.parametrize("kind", ["ekf", "ukf"])
def test_both_filters_follow_a_constant_velocity(kind):
    fusion = FusionFilter(FusionSettings(kind=kind))
    for k in range(200):
        z = np.zeros(15)
        z[state.VX] = 1.0
        fusion.enqueue(Measurement(k * 20_000_000, z, np.eye(15) * 1e-4, (6, 7, 8, 9, 10, 11)))
        fusion.update(k * 20_000_000)
    # 199 steps of 20 ms at 1 m/s along x. The UKF's first correction after each
    # prediction uses the propagated sigma points (the peer's order), which lag it by
    # 2.5% here; the EKF is exact.
    assert fusion.x[state.X] == pytest.approx(3.98, rel=0.03)
    assert np.all(np.isfinite(fusion.p))


def test_an_imu_at_rest_measures_no_acceleration_once_gravity_is_removed():
    level = np.eye(3)
    measured = inputs.acceleration(
        0, np.array([0.0, 0.0, inputs.GRAVITY]), np.eye(3) * 0.01, (False,) * 12 + (True,) * 3,
        np.zeros(3), np.zeros(3), level, remove_gravity=True)
    np.testing.assert_allclose(measured.z[12:15], 0.0, atol=1e-12)


def test_a_mount_turns_the_twist_and_its_mask():
    # A sensor turned 90 degrees about z: its x is the robot's y.
    mount = inputs.Mount.from_rpy((0.0, 0.0, 0.0), (0.0, 0.0, math.pi / 2))
    update = tuple(i == state.VX for i in range(15))
    measured = inputs.twist(0, np.array([1.0, 0.0, 0.0]), np.zeros(3), np.eye(6) * 0.1,
                            update, np.zeros(3), mount)
    assert measured.indices == (state.VY,)
    assert measured.z[state.VY] == pytest.approx(1.0)


def test_the_config_reads_the_peers_names_and_says_what_it_does_not_support():
    config = fusion_config({"frequency": 50.0, "odom0": "/odom",
                            "odom0_config": [False] * 6 + [True] * 3 + [False] * 6,
                            "publish_acceleration": True, "imu0": "/imu",
                            "imu0_config": [False] * 15})
    assert config.frequency == 50.0
    assert config.sensors["odom0"].update[6:9] == (True, True, True)
    assert config.unsupported == ("publish_acceleration",)
    with pytest.raises(FusionConfigError, match="process_noise_covariance: expected 225"):
        fusion_config({"process_noise_covariance": [1.0, 2.0]})
    with pytest.raises(FusionConfigError, match="frequency"):
        fusion_config({"frequency": 0})


# --- two_d_mode -------------------------------------------------------------------------

def vector3(values) -> SimpleNamespace:
    return SimpleNamespace(x=values[0], y=values[1], z=values[2])


def header(stamp_ns: int, frame: str) -> SimpleNamespace:
    sec, nanosec = divmod(stamp_ns, 1_000_000_000)
    return SimpleNamespace(stamp=SimpleNamespace(sec=sec, nanosec=nanosec), frame_id=frame)


def odometry_message(stamp_ns: int, linear=(0.0, 0.0, 0.0), angular=(0.0, 0.0, 0.0),
                     twist_covariance=None, position=(0.0, 0.0, 0.0),
                     quaternion=(0.0, 0.0, 0.0, 1.0), pose_covariance=None,
                     frame: str = "odom", child: str = "base_link") -> SimpleNamespace:
    """A nav_msgs/Odometry by its field names, as SensorInputs reads one."""
    twist_covariance = np.eye(6) * 0.01 if twist_covariance is None else twist_covariance
    pose_covariance = np.eye(6) * 0.01 if pose_covariance is None else pose_covariance
    orientation = SimpleNamespace(x=quaternion[0], y=quaternion[1], z=quaternion[2],
                                  w=quaternion[3])
    return SimpleNamespace(
        header=header(stamp_ns, frame), child_frame_id=child,
        pose=SimpleNamespace(pose=SimpleNamespace(position=vector3(position),
                                                  orientation=orientation),
                             covariance=list(np.ravel(pose_covariance))),
        twist=SimpleNamespace(twist=SimpleNamespace(linear=vector3(linear),
                                                    angular=vector3(angular)),
                              covariance=list(np.ravel(twist_covariance))))


def kalman_correction(x, p, z, r, idx):
    """The textbook correction with H the rows ``idx`` of the identity, angles wrapped."""
    h = np.eye(15)[idx]
    k = p @ h.T @ np.linalg.inv(h @ p @ h.T + r)
    innovation = z - h @ x
    for row, index in enumerate(idx):
        if index in state.ANGLES:
            innovation[row] = state.wrap(innovation[row])
    gain_residual = np.eye(15) - k @ h
    return (state.wrap_state_angles(x + k @ innovation),
            gain_residual @ p @ gain_residual.T + k @ r @ k.T)


TWIST_AND_YAW_RATE = tuple(i in (state.VX, state.VY, state.VYAW) for i in range(15))
PLANAR = [state.Z, state.ROLL, state.PITCH, state.VZ, state.VROLL, state.VPITCH, state.AZ]


def test_two_d_mode_measures_the_planar_zeros_with_the_peers_variance():
    z = RNG.normal(size=15)
    a = RNG.normal(size=(15, 15))
    covariance = a @ a.T
    measured = inputs.force_two_d(Measurement(5, z, covariance, (6, 7, 8, 11), 4.0, "odom0"))
    assert measured.indices == (2, 3, 4, 6, 7, 8, 9, 10, 11, 14)
    expected_z = z.copy()
    expected_z[PLANAR] = 0.0
    np.testing.assert_array_equal(measured.z, expected_z)
    kept = [6, 7, 11]
    np.testing.assert_array_equal(measured.covariance[np.ix_(kept, kept)],
                                  covariance[np.ix_(kept, kept)])
    np.testing.assert_array_equal(measured.covariance[np.ix_(PLANAR, PLANAR)],
                                  np.eye(7) * 1e-6)
    # The zeros are not correlated with what the sensor measured.
    assert not measured.covariance[np.ix_(PLANAR, kept)].any()
    assert (measured.stamp_ns, measured.threshold, measured.source) == (5, 4.0, "odom0")


def test_a_two_d_correction_is_the_kalman_correction_with_the_zeros_measured():
    x = random_state()
    a = RNG.normal(size=(15, 15))
    p = a @ a.T + np.eye(15)
    z = np.zeros(15)
    z[[state.VX, state.VY, state.VYAW]] = [1.2, -0.1, 0.3]
    covariance = np.diag(np.full(15, 0.04))
    forced = inputs.force_two_d(Measurement(0, z, covariance, (6, 7, 11)))
    x_new, p_new = steps.ekf_correct(x, p, forced)
    idx = sorted([6, 7, 11] + PLANAR)
    r = np.diag([1e-6 if i in PLANAR else 0.04 for i in idx])
    x_expected, p_expected = kalman_correction(x, p, z[idx], r, idx)
    np.testing.assert_allclose(x_new, x_expected, atol=1e-9)
    np.testing.assert_allclose(p_new, p_expected, atol=1e-9)


@pytest.mark.parametrize("kind", ["ekf", "ukf"])
def test_a_two_d_robots_file_keeps_the_estimate_in_the_plane(kind):
    """Odometry that says the robot climbs (vz) and rolls: in two_d_mode the state keeps
    z, roll and pitch at 0; without it, the climb is fused."""
    finals = {}
    for two_d in (False, True):
        config = fusion_config({"odom0": "odom", "two_d_mode": two_d, "filter_type": kind,
                                "odom0_config": [False] * 6 + [True] * 6 + [False] * 3})
        assert "two_d_mode" not in config.unsupported
        fusion = FusionFilter(config.settings)
        sensor_inputs = config.sensor_inputs()
        for k in range(100):
            stamp = k * 20_000_000
            sensor_inputs.add(config.sensors["odom0"],
                              odometry_message(stamp, (1.0, 0.0, 0.5), (0.2, 0.0, 0.1)), fusion)
            fusion.update(stamp)
        finals[two_d] = fusion.x.copy()
    assert finals[False][state.Z] > 0.5
    np.testing.assert_allclose(finals[True][PLANAR], 0.0, atol=1e-3)
    # The planar motion goes on: 1 m/s turning at 0.1 rad/s for 1.98 s (the UKF lags by a
    # few percent, as in test_both_filters_follow_a_constant_velocity).
    assert finals[True][state.YAW] == pytest.approx(0.198, abs=0.01)
    assert np.hypot(finals[True][state.X], finals[True][state.Y]) == pytest.approx(1.98,
                                                                                   rel=0.05)


# --- pose inputs: odomN pose entries, poseN; _relative, _differential --------------------

POSE_ONLY = tuple(i < 6 for i in range(15))


def pose_message(stamp_ns: int, position, quaternion, covariance, frame: str = "odom"
                 ) -> SimpleNamespace:
    """A geometry_msgs/PoseWithCovarianceStamped by its field names."""
    odometry = odometry_message(stamp_ns, position=position, quaternion=quaternion,
                                pose_covariance=covariance, frame=frame)
    return SimpleNamespace(header=odometry.header, pose=odometry.pose)


def random_quaternion() -> tuple[float, ...]:
    q = RNG.normal(size=4)
    return tuple(q / np.linalg.norm(q))


def random_covariance(size: int = 6) -> np.ndarray:
    a = RNG.normal(size=(size, size)) * 0.1
    return a @ a.T + np.eye(size) * 0.01


def rpy_of(transform: rigid.Transform) -> tuple[float, float, float]:
    return state.rpy_from_rotation(state.rotation_from_quaternion(*transform.rotation))


def pose_inputs(**sensor_parameters) -> tuple:
    """A config with one pose input ``pose0`` (all six entries), its inputs and a filter."""
    config = fusion_config({"pose0": "pose", "pose0_config": [True] * 15,
                            **sensor_parameters})
    return config, config.sensor_inputs({"gps_origin": GPS_ORIGIN}), FusionFilter(
        config.settings)


#: A pose input's frame placed in the world frame (odom): 10 m east, turned 30 degrees.
GPS_ORIGIN_TRANSFORM = rigid.Transform((10.0, -2.0, 0.5), state.quaternion_from_rpy(0.0, 0.0,
                                                                                      0.5236))
GPS_ORIGIN = inputs.Mount(state.rotation_from_quaternion(*GPS_ORIGIN_TRANSFORM.rotation),
                          np.array(GPS_ORIGIN_TRANSFORM.translation))


def queued(fusion: FusionFilter) -> list[Measurement]:
    return [entry[2] for entry in sorted(fusion._queue)]


def test_a_pose_in_a_placed_frame_is_measured_in_the_world_frame():
    config, sensor_inputs, fusion = pose_inputs()
    # The pose topic's config is cut to its pose entries, as the peer does.
    assert config.sensors["pose0"].update == POSE_ONLY
    position, quaternion, covariance = (1.0, 2.0, 0.3), random_quaternion(), random_covariance()
    sensor_inputs.add(config.sensors["pose0"],
                      pose_message(7, position, quaternion, covariance, "gps_origin"), fusion)
    (measured,) = queued(fusion)
    expected = GPS_ORIGIN_TRANSFORM * rigid.Transform(position, quaternion)
    assert measured.indices == tuple(range(6))
    np.testing.assert_allclose(measured.z[:3], expected.translation, atol=1e-9)
    np.testing.assert_allclose(measured.z[3:6], rpy_of(expected), atol=1e-9)
    turn = np.kron(np.eye(2), GPS_ORIGIN.rotation)
    np.testing.assert_allclose(measured.covariance[:6, :6], turn @ covariance @ turn.T,
                               atol=1e-9)
    assert (measured.stamp_ns, measured.source) == (7, "pose0")


def test_a_pose_correction_is_the_kalman_correction_of_the_world_pose():
    config, sensor_inputs, fusion = pose_inputs()
    fusion.initialized = True
    fusion.x = random_state()
    a = RNG.normal(size=(15, 15))
    fusion.p = a @ a.T + np.eye(15)
    x, p = fusion.x.copy(), fusion.p.copy()
    position, quaternion, covariance = (3.0, -1.0, 0.2), random_quaternion(), random_covariance()
    sensor_inputs.add(config.sensors["pose0"],
                      pose_message(0, position, quaternion, covariance, "odom"), fusion)
    fusion.update(0)
    z = np.array([*position, *rpy_of(rigid.Transform(position, quaternion))])
    x_expected, p_expected = kalman_correction(x, p, z, covariance, list(range(6)))
    np.testing.assert_allclose(fusion.x, x_expected, atol=1e-9)
    np.testing.assert_allclose(fusion.p, p_expected, atol=1e-9)


def test_a_mount_turns_the_pose_mask_with_the_frame():
    # A frame turned 90 degrees about z: its x is the world's y.
    frame = inputs.Mount.from_rpy((0.0, 0.0, 0.0), (0.0, 0.0, math.pi / 2))
    update = tuple(i == state.X for i in range(15))
    measured = inputs.pose(0, inputs.Mount(np.eye(3), np.array([2.0, 0.0, 0.0])),
                           np.eye(6), update, frame)
    assert measured.indices == (state.Y,)
    assert measured.z[state.Y] == pytest.approx(2.0)


def test_odometry_feeds_its_pose_and_its_twist_with_their_own_thresholds():
    config = fusion_config({"odom0": "odom", "odom0_config": [True] * 12 + [False] * 3,
                            "odom0_pose_rejection_threshold": 2.0,
                            "odom0_twist_rejection_threshold": 3.0})
    assert config.unsupported == ()
    fusion = FusionFilter(config.settings)
    config.sensor_inputs().add(config.sensors["odom0"], odometry_message(
        5, (1.0, 0.0, 0.0), position=(4.0, 5.0, 0.0)), fusion)
    pose_part, twist_part = queued(fusion)
    assert (pose_part.source, pose_part.threshold, pose_part.indices) == \
        ("odom0_pose", 2.0, tuple(range(6)))
    assert (twist_part.source, twist_part.threshold, twist_part.indices) == \
        ("odom0_twist", 3.0, tuple(range(6, 12)))
    np.testing.assert_allclose(pose_part.z[:3], [4.0, 5.0, 0.0])


def test_a_relative_pose_is_the_pose_since_the_first_one_placed_in_the_world():
    config, sensor_inputs, fusion = pose_inputs(pose0_relative=True)
    first = rigid.Transform((5.0, 1.0, 0.0), random_quaternion())
    later = rigid.Transform((6.0, 3.0, 0.4), random_quaternion())
    for stamp, pose in ((1, first), (2, later)):
        sensor_inputs.add(config.sensors["pose0"], pose_message(
            stamp, pose.translation, pose.rotation, np.eye(6) * 0.01, "gps_origin"), fusion)
    at_first, at_later = queued(fusion)
    # The first pose is the frame's origin; the later one is the motion since, placed.
    np.testing.assert_allclose(at_first.z[:3], GPS_ORIGIN_TRANSFORM.translation, atol=1e-9)
    np.testing.assert_allclose(at_first.z[3:6], rpy_of(GPS_ORIGIN_TRANSFORM), atol=1e-9)
    expected = GPS_ORIGIN_TRANSFORM * (first.inverse() * later)
    np.testing.assert_allclose(at_later.z[:3], expected.translation, atol=1e-9)
    np.testing.assert_allclose(at_later.z[3:6], rpy_of(expected), atol=1e-9)


def test_a_differential_pose_is_the_velocity_between_two_poses_with_the_peers_covariance():
    config, sensor_inputs, fusion = pose_inputs(pose0_differential=True, pose0_relative=True,
                                                pose0_rejection_threshold=5.0)
    assert config.sensors["pose0"].differential and not config.sensors["pose0"].relative
    first = rigid.Transform((5.0, 1.0, 0.0), state.quaternion_from_rpy(0.1, -0.2, 0.3))
    later = rigid.Transform((5.1, 1.05, 0.01), state.quaternion_from_rpy(0.11, -0.19, 0.35))
    c1, c2 = random_covariance(), random_covariance()
    # No transform is needed: the change between two poses is the same in any frame.
    for stamp, pose, covariance in ((1_000_000_000, first, c1), (1_250_000_000, later, c2)):
        sensor_inputs.add(config.sensors["pose0"], pose_message(
            stamp, pose.translation, pose.rotation, covariance, "unknown_frame"), fusion)
    (measured,) = queued(fusion)
    dt = 0.25
    r0 = state.rotation_from_quaternion(*first.rotation)
    r1 = state.rotation_from_quaternion(*later.rotation)
    linear = r0.T @ (np.array(later.translation) - np.array(first.translation)) / dt
    angular = np.array(state.rpy_from_rotation(r0.T @ r1)) / dt
    assert measured.indices == tuple(range(6, 12))
    assert (measured.source, measured.threshold, measured.stamp_ns) == \
        ("pose0", 5.0, 1_250_000_000)
    np.testing.assert_allclose(measured.z[6:12], [*linear, *angular], atol=1e-9)
    np.testing.assert_allclose(measured.covariance[6:12, 6:12], (c1 + c2) * dt, atol=1e-12)
    assert sensor_inputs.dropped == {}


def test_a_differential_pose_at_the_time_of_the_last_one_is_dropped():
    config, sensor_inputs, fusion = pose_inputs(pose0_differential=True)
    for _ in range(2):
        sensor_inputs.add(config.sensors["pose0"], pose_message(
            3, (1.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0), np.eye(6) * 0.01), fusion)
    assert fusion.queued == 0
    assert sensor_inputs.dropped == {
        "pose0: at the time of the one before, no velocity to take": 1}


@pytest.mark.parametrize(("frame", "position", "reason"), [
    ("base_link", (1.0, 0.0, 0.0), "pose0: no transform from 'base_link' to 'odom'"),
    ("", (1.0, 0.0, 0.0), "pose0: no transform from '' to 'odom'"),
    ("odom", (math.nan, 0.0, 0.0), "pose0: a non-finite value"),
])
def test_a_pose_that_cannot_be_placed_or_read_is_dropped_with_its_reason(frame, position,
                                                                         reason):
    config, sensor_inputs, fusion = pose_inputs(pose0_relative=True)
    sensor_inputs.add(config.sensors["pose0"], pose_message(
        1, position, (0.0, 0.0, 0.0, 1.0), np.eye(6) * 0.01, frame), fusion)
    assert fusion.queued == 0
    assert sensor_inputs.dropped == {reason: 1}
    # Nothing was remembered as the first pose: the next good one is.
    sensor_inputs.add(config.sensors["pose0"], pose_message(
        2, (2.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0), np.eye(6) * 0.01), fusion)
    np.testing.assert_allclose(queued(fusion)[0].z[:6], 0.0, atol=1e-12)


def test_a_pose_beyond_its_rejection_threshold_is_rejected():
    config, sensor_inputs, fusion = pose_inputs(pose0_rejection_threshold=3.0)
    for stamp, x in ((0, 0.0), (10_000_000, 50.0)):
        sensor_inputs.add(config.sensors["pose0"], pose_message(
            stamp, (x, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0), np.eye(6) * 0.01), fusion)
        fusion.update(stamp)
    assert fusion.counts.applied == {"pose0": 1}
    assert fusion.counts.rejected == {"pose0": 1}
    assert fusion.x[state.X] == pytest.approx(0.0, abs=1e-6)


def test_the_config_takes_the_peers_threshold_names_per_kind():
    config = fusion_config({"twist0": "twist", "twist0_config": [False] * 6 + [True] * 6 +
                            [False] * 3, "twist0_rejection_threshold": 4.0,
                            "twist0_pose_rejection_threshold": 2.0})
    assert config.sensors["twist0"].twist_threshold == 4.0
    # A twist topic has no pose threshold in the peer: said, not silently taken.
    assert config.unsupported == ("twist0_pose_rejection_threshold",)


# --- a covariance that cannot be one ---------------------------------------------------

def twist_covariance(vx_vy_block) -> np.ndarray:
    covariance = np.eye(6) * 0.01
    covariance[:2, :2] = vx_vy_block
    return covariance


@pytest.mark.parametrize(("block", "reason"), [
    # Correlation 2: eigenvalues 3 and -1.
    ([[1.0, 2.0], [2.0, 1.0]], "a covariance that is not symmetric positive semi-definite"),
    ([[1.0, 0.5], [0.0, 1.0]], "a covariance that is not symmetric positive semi-definite"),
    ([[1.0, math.nan], [math.nan, 1.0]], "a non-finite covariance"),
    ([[math.inf, 0.0], [0.0, 1.0]], "a non-finite covariance"),
])
def test_a_measurement_whose_covariance_cannot_be_one_is_dropped_with_the_reason(block,
                                                                                   reason):
    config = fusion_config({"odom0": "odom", "odom0_config": list(TWIST_AND_YAW_RATE)})
    fusion = FusionFilter(config.settings)
    sensor_inputs = config.sensor_inputs()
    sensor_inputs.add(config.sensors["odom0"], odometry_message(0, (1.0, 0.0, 0.0)), fusion)
    fusion.update(0)
    x, p = fusion.x.copy(), fusion.p.copy()
    made = sensor_inputs.add(config.sensors["odom0"], odometry_message(
        0, (2.0, 0.5, 0.0), twist_covariance=twist_covariance(block)), fusion)
    fusion.update(0)
    assert made == 0
    assert sensor_inputs.dropped == {f"odom0_twist: {reason}": 1}
    np.testing.assert_array_equal(fusion.x, x)
    np.testing.assert_array_equal(fusion.p, p)


def test_an_indefinite_covariance_of_entries_not_measured_is_not_read_but_a_nan_is():
    config = fusion_config({"odom0": "odom", "odom0_config": list(TWIST_AND_YAW_RATE)})
    covariance = np.eye(6) * 0.01
    covariance[3, 4] = covariance[4, 3] = 5.0       # vroll-vpitch: indefinite, not measured
    fusion = FusionFilter(config.settings)
    sensor_inputs = config.sensor_inputs()
    assert sensor_inputs.add(config.sensors["odom0"], odometry_message(
        0, (1.0, 0.0, 0.0), twist_covariance=covariance), fusion) == 1
    assert sensor_inputs.dropped == {}
    # A NaN anywhere would spread through the frame's rotation to every entry.
    covariance[2, 2] = math.nan                     # vz: not in the config
    assert sensor_inputs.add(config.sensors["odom0"], odometry_message(
        1, (1.0, 0.0, 0.0), twist_covariance=covariance), fusion) == 0
    assert sensor_inputs.dropped == {"odom0_twist: a non-finite covariance": 1}


def test_the_covariance_check_of_a_measurement_made_elsewhere():
    z = np.zeros(15)
    good, indefinite, nan = np.eye(15), np.eye(15), np.eye(15)
    indefinite[6, 7] = indefinite[7, 6] = 3.0
    nan[7, 7] = math.nan
    assert steps.covariance_problem(Measurement(0, z, good, (6, 7))) is None
    assert steps.covariance_problem(Measurement(0, z, indefinite, (6, 7))) == \
        "a covariance that is not symmetric positive semi-definite"
    assert steps.covariance_problem(Measurement(0, z, nan, (6, 7))) == \
        "a non-finite covariance"


@pytest.mark.parametrize("kind", ["ekf", "ukf"])
def test_a_negative_or_zero_variance_is_taken_as_the_peer_takes_it(kind):
    """|variance|, at least 1e-9: also when the measurement initializes the filter, so P
    never starts with a negative variance."""
    config = fusion_config({"odom0": "odom", "odom0_config": list(TWIST_AND_YAW_RATE),
                            "filter_type": kind})
    fusion = FusionFilter(config.settings)
    sensor_inputs = config.sensor_inputs()
    covariance = np.diag([-0.04, 0.0, 1.0, 1.0, 1.0, 0.09])
    sensor_inputs.add(config.sensors["odom0"], odometry_message(
        0, (1.0, 0.0, 0.0), twist_covariance=covariance), fusion)
    fusion.update(0)
    measured = [state.VX, state.VY, state.VYAW]
    np.testing.assert_array_equal(np.diag(fusion.p)[measured], [0.04, 1e-9, 0.09])
    assert np.all(np.linalg.eigvalsh(fusion.p) > 0)
    if kind == "ekf":
        x, p = fusion.x.copy(), fusion.p.copy()
        sensor_inputs.add(config.sensors["odom0"], odometry_message(
            0, (1.5, 0.1, 0.0), (0.0, 0.0, 0.2), covariance), fusion)
        fusion.update(0)
        x_expected, p_expected = kalman_correction(
            x, p, np.array([1.5, 0.1, 0.2]), np.diag([0.04, 1e-9, 0.09]), measured)
        np.testing.assert_allclose(fusion.x, x_expected, atol=1e-9)
        np.testing.assert_allclose(fusion.p, p_expected, atol=1e-9)


# --- set_pose ----------------------------------------------------------------------------

def test_set_pose_puts_the_state_at_the_placed_pose_and_forgets_the_inputs_history():
    config, sensor_inputs, fusion = pose_inputs(pose0_relative=True)
    pose0 = config.sensors["pose0"]
    for stamp in (1, 2):
        sensor_inputs.add(pose0, pose_message(stamp, (5.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0),
                                              np.eye(6) * 0.01), fusion)
    fusion.update(1)                    # the second one stays queued
    position, quaternion, covariance = (1.0, 2.0, 0.3), random_quaternion(), random_covariance()
    assert sensor_inputs.set_pose(pose_message(10, position, quaternion, covariance,
                                               "gps_origin"), fusion, now_ns=50)
    placed = GPS_ORIGIN_TRANSFORM * rigid.Transform(position, quaternion)
    expected_x = np.zeros(15)
    expected_x[:3] = placed.translation
    expected_x[3:6] = rpy_of(placed)
    turn = np.kron(np.eye(2), GPS_ORIGIN.rotation)
    expected_p = np.eye(15) * 1e-6
    expected_p[:6, :6] = turn @ covariance @ turn.T
    np.testing.assert_allclose(fusion.x, expected_x, atol=1e-9)
    np.testing.assert_allclose(fusion.p, expected_p, atol=1e-9)
    assert (fusion.queued, fusion.last_time_ns) == (0, 50)
    # What is not later than the set pose is dropped; the first later pose is the new
    # origin of the relative input.
    assert sensor_inputs.add(pose0, pose_message(10, (7.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0),
                                                 np.eye(6) * 0.01), fusion) == 0
    assert sensor_inputs.dropped == {"pose0: not after the last set_pose": 1}
    sensor_inputs.add(pose0, pose_message(11, (7.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0),
                                          np.eye(6) * 0.01), fusion)
    np.testing.assert_allclose(queued(fusion)[0].z[:6], 0.0, atol=1e-12)


def test_set_pose_in_two_d_mode_holds_the_plane_and_a_bad_one_changes_nothing():
    config = fusion_config({"two_d_mode": True})
    fusion = FusionFilter(config.settings)
    sensor_inputs = config.sensor_inputs()
    tilted = state.quaternion_from_rpy(0.3, 0.2, 1.0)
    assert sensor_inputs.set_pose(pose_message(1, (1.0, 2.0, 3.0), tilted, np.eye(6) * 0.5),
                                  fusion, now_ns=1)
    expected_x = np.zeros(15)
    expected_x[[state.X, state.Y, state.YAW]] = [1.0, 2.0, 1.0]
    np.testing.assert_allclose(fusion.x, expected_x, atol=1e-9)
    np.testing.assert_allclose(np.diag(fusion.p)[:6], [0.5, 0.5, 1e-6, 1e-6, 1e-6, 0.5])
    x, p = fusion.x.copy(), fusion.p.copy()
    indefinite = np.eye(6)
    indefinite[0, 1] = indefinite[1, 0] = 2.0
    assert not sensor_inputs.set_pose(pose_message(2, (9.0, 9.0, 0.0), tilted, indefinite),
                                      fusion, now_ns=2)
    assert not sensor_inputs.set_pose(pose_message(3, (9.0, 9.0, 0.0), tilted, np.eye(6),
                                                   "nowhere"), fusion, now_ns=3)
    np.testing.assert_array_equal(fusion.x, x)
    np.testing.assert_array_equal(fusion.p, p)
    assert sensor_inputs.dropped == {
        "set_pose: a covariance that is not symmetric positive semi-definite": 1,
        "set_pose: no transform from 'nowhere' to 'odom'": 1}
    assert sensor_inputs.last_dropped == "set_pose: no transform from 'nowhere' to 'odom'"


# --- an IMU's orientation: _relative and _differential ---------------------------------

def imu_message(stamp_ns: int, quaternion, orientation_covariance, frame: str = "imu_link"
                ) -> SimpleNamespace:
    """A sensor_msgs/Imu by its field names, with orientation only."""
    absent = [-1.0] + [0.0] * 8
    return SimpleNamespace(
        header=header(stamp_ns, frame),
        orientation=SimpleNamespace(x=quaternion[0], y=quaternion[1], z=quaternion[2],
                                    w=quaternion[3]),
        orientation_covariance=list(np.ravel(orientation_covariance)),
        angular_velocity=vector3((0.0, 0.0, 0.0)), angular_velocity_covariance=absent,
        linear_acceleration=vector3((0.0, 0.0, 0.0)), linear_acceleration_covariance=absent)


#: An IMU mounted turned a quarter to the left and tilted: its pitch is the robot's roll.
IMU_MOUNT_RPY = (0.1, -0.05, math.pi / 2)
#: Which way the mount's yaw turns roll and pitch: (roll, pitch) -> (-pitch, roll).
IMU_TURN = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


def imu_attitude_by_hand(rpy) -> rigid.Transform:
    """The peer's recipe, written out: the mount's angles off, the roll/pitch pair turned."""
    offsets = [state.wrap(a - b) for a, b in zip(rpy, IMU_MOUNT_RPY)]
    return rigid.Transform(rotation=state.quaternion_from_rpy(*(IMU_TURN @ offsets)))


def imu_inputs(config_flags, **parameters):
    config = fusion_config({"imu0": "imu", "imu0_config": [i in config_flags for i in range(15)],
                            **parameters})
    mounts = {"imu_link": inputs.Mount.from_rpy((0.0, -0.3, 0.5), IMU_MOUNT_RPY)}
    return config, config.sensor_inputs(mounts), FusionFilter(config.settings)


def test_a_relative_imu_measures_its_attitude_since_its_first_one():
    config, sensor_inputs, fusion = imu_inputs((state.ROLL, state.PITCH, state.YAW),
                                               imu0_relative=True)
    first, later = (0.3, -0.2, 1.0), (0.35, -0.1, 1.4)
    covariance = random_covariance(3)
    for stamp, rpy in ((1, first), (2, later)):
        sensor_inputs.add(config.sensors["imu0"], imu_message(
            stamp, state.quaternion_from_rpy(*rpy), covariance), fusion)
    at_first, at_later = queued(fusion)
    np.testing.assert_allclose(at_first.z[3:6], 0.0, atol=1e-12)
    expected = imu_attitude_by_hand(first).inverse() * imu_attitude_by_hand(later)
    np.testing.assert_allclose(at_later.z[3:6], rpy_of(expected), atol=1e-9)
    np.testing.assert_allclose(at_later.covariance[3:6, 3:6],
                               IMU_TURN @ covariance @ IMU_TURN.T, atol=1e-12)


def test_a_differential_imu_measures_the_rates_between_two_attitudes():
    # Roll and yaw configured: the mount's quarter turn makes them pitch and yaw rates.
    config, sensor_inputs, fusion = imu_inputs((state.X, state.ROLL, state.YAW),
                                               imu0_differential=True,
                                               imu0_pose_rejection_threshold=4.0)
    assert config.unsupported == ()
    first, later = (0.3, -0.2, 1.0), (0.32, -0.17, 1.1)
    c1, c2 = random_covariance(3), random_covariance(3)
    for stamp, rpy, covariance in ((0, first, c1), (100_000_000, later, c2)):
        sensor_inputs.add(config.sensors["imu0"], imu_message(
            stamp, state.quaternion_from_rpy(*rpy), covariance), fusion)
    (measured,) = queued(fusion)
    change = imu_attitude_by_hand(first).inverse() * imu_attitude_by_hand(later)
    assert measured.indices == (state.VPITCH, state.VYAW)
    assert (measured.source, measured.threshold) == ("imu0_pose", 4.0)
    np.testing.assert_allclose(measured.z[9:12], np.array(rpy_of(change)) / 0.1, atol=1e-9)
    np.testing.assert_allclose(measured.covariance[9:12, 9:12],
                               IMU_TURN @ (c1 + c2) @ IMU_TURN.T * 0.1, atol=1e-12)


def test_rclpys_own_parameters_are_no_unsupported_ones():
    """Every rclpy node declares use_sim_time and start_type_description_service: neither
    is a robot_localization parameter we do not support."""
    config = fusion_config({"odom0": "odom", "use_sim_time": True,
                            "start_type_description_service": True, "frequencyy": 3.0})
    assert config.unsupported == ("frequencyy",)
