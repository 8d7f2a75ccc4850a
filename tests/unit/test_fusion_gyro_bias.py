"""An IMU's gyro bias as state (``imuN_gyro_bias``, beyond robot_localization): the steps
with the bias's entries against the direct Kalman computation, and a robot whose gyro
reads 0.03 rad/s too much beside wheel odometry that does not."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from estimation_nodes.core.fusion import inputs, state, steps
from estimation_nodes.core.fusion.filter import FusionFilter
from estimation_nodes.core.fusion.steps import Measurement, UnscentedWeights
from estimation_nodes.params.fusion import FusionConfigError, fusion_config
from tests.unit.test_fusion_core import header, odometry_message, vector3

RNG = np.random.default_rng(11)
SIZE = state.STATE_SIZE + state.GYRO_BIAS_SIZE
BIAS = state.STATE_SIZE          # the yaw rate's bias is BIAS + 2


def random_covariance(size: int) -> np.ndarray:
    a = RNG.normal(size=(size, size))
    return a @ a.T / size + np.eye(size) * 0.1


def gyro_reading(values=(0.1, -0.2, 0.3)) -> Measurement:
    z = np.zeros(15)
    z[state.VROLL:state.VROLL + 3] = values
    rates = (state.VROLL, state.VPITCH, state.VYAW)
    return Measurement(0, z, np.eye(15) * 0.01, rates,
                       biased=tuple((index, BIAS + i) for i, index in enumerate(rates)))


def kalman_correction(x, p, z, r, h):
    """The textbook's correction with H written out (Joseph form)."""
    k = p @ h.T @ np.linalg.inv(h @ p @ h.T + r)
    residual = np.eye(len(x)) - k @ h
    return x + k @ (z - h @ x), residual @ p @ residual.T + k @ r @ k.T


@pytest.mark.parametrize("kind", ["ekf", "ukf"])
def test_a_biased_reading_is_the_kalman_correction_of_rate_plus_bias(kind):
    x, p = RNG.normal(size=SIZE) * 0.1, random_covariance(SIZE)
    measurement = gyro_reading()
    h = np.zeros((3, SIZE))
    for row in range(3):
        h[row, state.VROLL + row] = h[row, BIAS + row] = 1.0
    expected = kalman_correction(x, p, measurement.z[9:12], np.eye(3) * 0.01, h)
    np.testing.assert_array_equal(steps.observation_matrix(measurement, SIZE), h)
    if kind == "ekf":
        got = steps.ekf_correct(x, p, measurement)
    else:
        got = steps.ukf_correct(x, p, measurement, UnscentedWeights(size=SIZE), None)
        # The peer's UKF takes K (H P H') K' off P, without R (steps.py's twin).
        k = p @ h.T @ np.linalg.inv(h @ p @ h.T + np.eye(3) * 0.01)
        expected = (expected[0], p - k @ h @ p @ h.T @ k.T)
    # The unscented transform is exact for a linear reading; its weights of -1e6 leave
    # rounding of some 1e-10 in the covariance.
    np.testing.assert_allclose(got[0], expected[0], rtol=0, atol=1e-12 if kind == "ekf"
                               else 1e-9)
    np.testing.assert_allclose(got[1], expected[1], rtol=0, atol=1e-12 if kind == "ekf"
                               else 1e-9)


def test_the_biases_are_constant_in_the_motion_and_walk_by_their_noise():
    x, p = RNG.normal(size=SIZE) * 0.1, random_covariance(SIZE)
    p[:15, 15:] = p[15:, :15] = 0.0
    q = np.diag(np.r_[np.full(15, 0.01), np.full(3, 1e-6)])
    moved, spread = steps.ekf_predict(x, p, q, 0.05)
    plain_x, plain_p = steps.ekf_predict(x[:15].copy(), p[:15, :15].copy(), q[:15, :15], 0.05)
    np.testing.assert_allclose(moved[:15], plain_x, rtol=0, atol=1e-12)   # the kernel's
    np.testing.assert_allclose(spread[:15, :15], plain_p, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(moved[15:], x[15:])
    np.testing.assert_allclose(spread[15:, 15:], p[15:, 15:] + 0.05 * q[15:, 15:], atol=1e-15)


def imu_rates(stamp_ns: int, rates, variance: float) -> SimpleNamespace:
    """A sensor_msgs/Imu by its field names, with its angular rates only."""
    absent = [-1.0] + [0.0] * 8
    return SimpleNamespace(
        header=header(stamp_ns, "base_link"),
        orientation=SimpleNamespace(x=0.0, y=0.0, z=0.0, w=1.0), orientation_covariance=absent,
        angular_velocity=vector3(rates),
        angular_velocity_covariance=list(np.ravel(np.eye(3) * variance)),
        linear_acceleration=vector3((0.0, 0.0, 0.0)), linear_acceleration_covariance=absent)


WHEELS = [False] * 6 + [True, False, False, False, False, True] + [False] * 3
GYRO = [False] * 9 + [True] * 3 + [False] * 3


def turning_robot(kind: str, estimate_bias: bool, seconds: float = 20.0,
                  **parameters) -> FusionFilter:
    """0.5 m/s and 0.2 rad/s for ``seconds``: wheel odometry at 20 Hz (its yaw rate with
    variance 1e-4), a gyro at 50 Hz reading 0.03 rad/s too much on yaw, both noisy.
    ``mean_turn`` is the estimate's yaw rate averaged over the run's second half (one
    estimate follows the last readings' noise)."""
    config = fusion_config({"filter_type": kind, "two_d_mode": True, "odom0": "odom",
                            "odom0_config": WHEELS, "imu0": "imu", "imu0_config": GYRO,
                            "imu0_gyro_bias": estimate_bias, **parameters})
    fusion = FusionFilter(config.settings)
    sensor_inputs = config.sensor_inputs()
    odom, imu = config.sensors["odom0"], config.sensors["imu0"]
    rng = np.random.default_rng(3)
    turns = []
    twist_covariance = np.diag([1e-4, 1e-4, 1e-4, 1e-4, 1e-4, 1e-4])
    for step in range(int(seconds * 100)):
        t_ns = step * 10_000_000
        if step % 2 == 0:
            sensor_inputs.add(imu, imu_rates(t_ns, (0.0, 0.0, 0.23 + rng.normal(0, 0.01)),
                                             1e-4), fusion)
        if step % 5 == 1:
            sensor_inputs.add(odom, odometry_message(
                t_ns, linear=(0.5 + rng.normal(0, 0.01), 0.0, 0.0),
                angular=(0.0, 0.0, 0.2 + rng.normal(0, 0.01)),
                twist_covariance=twist_covariance), fusion)
        fusion.update(t_ns)
        if step * 2 >= seconds * 100:
            turns.append(fusion.x[state.VYAW])
    assert not sensor_inputs.dropped
    fusion.mean_turn = float(np.mean(turns))   # over the second half
    return fusion


@pytest.mark.parametrize("kind", ["ekf", "ukf"])
def test_the_gyros_bias_is_found_from_the_wheels_and_taken_out_of_the_turn(kind):
    fusion = turning_robot(kind, estimate_bias=True)
    assert fusion.x.shape == (SIZE,)
    assert fusion.x[BIAS + 2] == pytest.approx(0.03, abs=0.003)
    assert fusion.mean_turn == pytest.approx(0.2, abs=0.003)
    assert fusion.p[BIAS + 2, BIAS + 2] < 1e-3 / 10     # it learnt the bias
    # Without the bias state the turn is the gyro's and the wheels' compromise.
    plain = turning_robot(kind, estimate_bias=False)
    assert plain.x.shape == (15,)
    assert plain.mean_turn > 0.21


def test_the_yaw_drifts_less_with_the_bias_estimated():
    """The heading integrates the turn: 0.03 rad/s, half of it taken, is 0.3 rad in 20 s."""
    truth = 0.2 * 19.99
    with_bias = turning_robot("ekf", estimate_bias=True)
    plain = turning_robot("ekf", estimate_bias=False)
    error_with = abs(state.wrap(with_bias.x[state.YAW] - truth))
    error_plain = abs(state.wrap(plain.x[state.YAW] - truth))
    assert error_plain > 0.3 and error_with < 0.05


def test_two_d_mode_keeps_the_bias_on_the_yaw_rate_alone():
    reading = inputs.force_two_d(gyro_reading())
    assert reading.biased == ((state.VYAW, BIAS + 2),)


def test_set_pose_keeps_the_biases():
    fusion = turning_robot("ekf", estimate_bias=True, seconds=5.0)
    bias, variance = fusion.x[BIAS + 2], fusion.p[BIAS + 2, BIAS + 2]
    pose = Measurement(fusion.last_time_ns, np.zeros(15), np.eye(15) * 0.01,
                       (state.X, state.Y, state.YAW))
    fusion.set_pose(pose, fusion.last_time_ns)
    assert fusion.x[BIAS + 2] == bias and fusion.p[BIAS + 2, BIAS + 2] == variance
    assert fusion.x[state.VYAW] == 0.0


def test_the_parameters_grow_the_state_and_are_checked():
    config = fusion_config({"imu0": "a", "imu0_config": GYRO, "imu1": "b", "imu1_config": GYRO,
                            "imu0_gyro_bias": True, "imu1_gyro_bias": True,
                            "imu1_gyro_bias_variance": 0.5,
                            "imu1_gyro_bias_process_noise": 1e-6})
    assert not config.unsupported
    assert (config.sensors["imu0"].gyro_bias, config.sensors["imu1"].gyro_bias) == (15, 18)
    settings = config.settings
    assert settings.initial_state.shape == (21,) and settings.weights.size == 21
    np.testing.assert_array_equal(np.diag(settings.initial_covariance)[15:],
                                  [1e-3] * 3 + [0.5] * 3)
    np.testing.assert_array_equal(np.diag(settings.process_noise)[15:], [1e-8] * 3 + [1e-6] * 3)
    assert not np.any(settings.process_noise[:15, 15:])
    unused = fusion_config({"imu0": "a", "imu0_config": GYRO, "imu0_gyro_bias_variance": 0.5})
    assert unused.notes == ("imu0_gyro_bias_variance is given but imu0_gyro_bias is not "
                            "true: not used",)
    with pytest.raises(FusionConfigError, match="imu0_gyro_bias_process_noise"):
        fusion_config({"imu0": "a", "imu0_config": GYRO, "imu0_gyro_bias_process_noise": -1})
    for name, value, message in [
            ("imu0_gyro_bias", "yes", "imu0_gyro_bias: expected true or false"),
            ("imu0_gyro_bias_variance", -1.0, "imu0_gyro_bias_variance: expected a positive"),
            ("imu0_gyro_bias_process_noise", math.inf, "expected a positive")]:
        with pytest.raises(FusionConfigError, match=message):
            fusion_config({"imu0": "a", "imu0_config": GYRO, "imu0_gyro_bias": True,
                           name: value})


def test_a_first_reading_of_a_biased_gyro_starts_the_rate_with_the_bias_doubt():
    """The rate is the reading less the bias (0 at first), with the reading's variance
    plus the bias's, and the two tied: the joint Gaussian of rate = reading - bias."""
    config = fusion_config({"imu0": "imu", "imu0_config": GYRO, "imu0_gyro_bias": True})
    fusion = FusionFilter(config.settings)
    measurement = gyro_reading()
    fusion.process(measurement)
    rates = slice(state.VROLL, state.VROLL + 3)
    np.testing.assert_array_equal(fusion.x[rates], [0.1, -0.2, 0.3])
    np.testing.assert_allclose(np.diag(fusion.p)[rates], 0.01 + 1e-3)
    np.testing.assert_allclose(np.diag(fusion.p[rates, BIAS:BIAS + 3]), -1e-3)
    assert np.all(np.linalg.eigvalsh(fusion.p) > 0)
