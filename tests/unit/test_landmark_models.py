"""The landmark filter's models for real robots: a camera that reports depth, the iterated
EKF, and odometry that reports commands (followed late, at a share of their speed)."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from estimation_nodes.core.compiled_loader import load_kernels
from estimation_nodes.core.kalman import ekf, range_bearing, ukf, unicycle
from estimation_nodes.core.kalman.landmarks import LandmarkLocalization, LandmarkModel, Observation
from estimation_nodes.core.kalman.range_bearing import Ranging, SensorPose
from estimation_nodes.core.kalman.unicycle import UnicycleNoise, wrap
from estimation_nodes.params.landmarks import landmark_model
from estimation_nodes.params.param_files import read_node_parameters
from estimation_nodes.params.specs import LANDMARK_MODEL_SPECS, spec_defaults

SENSOR = SensorPose(0.05, -0.02, 0.03)
NOISE = UnicycleNoise(4e-4, 3e-3, 1e-6, 1e-4, 1.2e-2, 1.2e-3)
DEPTH = Ranging("depth", 1.035)


def numeric_jacobian(function, x):
    columns = []
    for i in range(x.size):
        step = np.zeros_like(x)
        step[i] = 1e-6
        columns.append(range_bearing.residual(function(x + step), function(x - step)) / 2e-6)
    return np.column_stack(columns)


def model(**changes) -> LandmarkModel:
    base = LandmarkModel("ekf", NOISE, 0.01, 0.02, 0.02, SENSOR, {6: (2.0, 1.0), 7: (0.5, 3.0)},
                         1.0, 5.0, (1.0, 0.5))
    return replace(base, **changes)


def test_depth_is_the_distance_along_the_sensors_axis_times_the_scale():
    x = np.array([0.3, -0.2, 0.4])
    landmark = (3.0, 1.5)
    distance, bearing = range_bearing.expected(x, landmark, SENSOR)
    depth, same_bearing = range_bearing.expected(x, landmark, SENSOR, DEPTH)
    assert depth == pytest.approx(1.035 * distance * math.cos(bearing), rel=1e-12)
    assert same_bearing == bearing


@pytest.mark.parametrize("ranging", [Ranging(), Ranging("euclidean", 0.97), DEPTH])
@pytest.mark.parametrize("pose", [(1.0, 2.0, 0.7), (-0.3, 0.4, -2.9), (0.0, 0.0, math.pi - 1e-3)])
def test_the_jacobian_of_each_ranging_is_its_derivative(ranging, pose):
    x = np.array(pose)
    for landmark in [(2.0, 1.0), (-1.5, 2.5), (0.5, -2.0)]:
        expected = numeric_jacobian(
            lambda s, lm=landmark: range_bearing.expected(s, lm, SENSOR, ranging), x)
        np.testing.assert_allclose(range_bearing.jacobian(x, landmark, SENSOR, ranging),
                                   expected, atol=1e-7)


def test_a_ranging_that_cannot_be_is_refused():
    with pytest.raises(ValueError, match="range_model"):
        Ranging("stereo")
    for scale in (0.0, -1.0, math.inf, math.nan):
        with pytest.raises(ValueError, match="range_scale"):
            Ranging("depth", scale)


def test_the_mount_covariance_is_the_spread_a_mount_error_gives_the_robots_pose():
    # The observations fix the sensor's pose; the robot's is sensor_pose behind it. Its
    # Jacobian in the mount, numerically, against the written-out covariance.
    from estimation_nodes.core.kalman.relocalization import robot_pose

    rng = np.random.default_rng(9)
    for _ in range(20):
        x = np.array([*rng.normal(0, 2, 2), rng.uniform(-math.pi, math.pi)])
        mount = rng.normal(0, 0.1, 3)
        std = rng.uniform(0, 0.05, 3)
        c, s = math.cos(x[2]), math.sin(x[2])
        seen_from = (x[0] + c * mount[0] - s * mount[1], x[1] + s * mount[0] + c * mount[1],
                     x[2] + mount[2])

        columns = []
        for i in range(3):
            step = np.zeros(3)
            step[i] = 1e-6
            ahead = robot_pose(seen_from, SensorPose(*(mount + step)))
            behind = robot_pose(seen_from, SensorPose(*(mount - step)))
            columns.append(np.r_[ahead[:2] - behind[:2], wrap(ahead[2] - behind[2])] / 2e-6)
        J = np.column_stack(columns)
        expected = J @ np.diag(std ** 2) @ J.T
        got = range_bearing.mount_covariance(x, SensorPose(*mount), tuple(std))
        np.testing.assert_allclose(got, expected, atol=1e-10)


def test_the_published_covariance_adds_the_mounts_and_the_filters_own_does_not():
    exact = LandmarkLocalization(model(), [0.5, 0.2, 0.7], np.eye(3) * 0.01, 0.0)
    np.testing.assert_array_equal(exact.pose_covariance, exact.P)
    std = (0.02, 0.01, 0.006)
    known = LandmarkLocalization(model(sensor_pose_std=std), [0.5, 0.2, 0.7],
                                 np.eye(3) * 0.01, 0.0)
    np.testing.assert_array_equal(known.P, exact.P)
    np.testing.assert_allclose(known.pose_covariance - known.P,
                               range_bearing.mount_covariance(known.x, SENSOR, std))
    for bad in ((0.02, 0.01), (-0.01, 0.0, 0.0), (math.nan, 0.0, 0.0), (0.0, 0.0, 2.0)):
        with pytest.raises(ValueError, match="sensor_pose_std"):
            model(sensor_pose_std=bad)


def _iterated(x, P, z, landmark, R, iterations):
    observed = ekf.innovation(x, P, z, landmark, SENSOR, R, DEPTH)
    x_next, P_next, _ = ekf.correct_iterated(x, P, observed, z, landmark, SENSOR, R, DEPTH,
                                             iterations)
    return x_next, P_next


def test_one_pass_of_the_iterated_ekf_is_the_ekf():
    x, P = np.array([0.0, 0.0, 0.2]), np.diag([0.04, 0.04, 0.05])
    R = np.diag([0.05 ** 2, 0.02 ** 2])
    z = np.array([2.5, 0.3])
    plain = ekf.correct(x, P, ekf.innovation(x, P, z, (3.0, 1.0), SENSOR, R, DEPTH), R)
    once = _iterated(x, P, z, (3.0, 1.0), R, 1)
    np.testing.assert_array_equal(once[0], plain[0])
    np.testing.assert_array_equal(once[1], plain[1])


def test_the_iterated_ekf_finds_the_mode_of_the_posterior():
    # A heading 30 degrees uncertain: the posterior's mode minimizes
    # (x - x0)' P^-1 (x - x0) + (z - h(x))' R^-1 (z - h(x)); its gradient there is zero.
    x0, P = np.array([0.0, 0.0, 0.5]), np.diag([0.01, 0.01, math.radians(30) ** 2])
    R = np.diag([0.03 ** 2, 0.01 ** 2])
    landmark = (3.0, 0.0)
    truth = np.array([0.05, -0.05, 0.05])
    z = range_bearing.expected(truth, landmark, SENSOR, DEPTH)

    def terms(x):
        dx = x - x0
        dx[2] = wrap(dx[2])
        y = range_bearing.residual(z, range_bearing.expected(x, landmark, SENSOR, DEPTH))
        return dx, y

    def gradient(x):
        dx, y = terms(x)
        H = range_bearing.jacobian(x, landmark, SENSOR, DEPTH)
        return np.linalg.solve(P, dx) - H.T @ np.linalg.solve(R, y)

    def cost(x):
        dx, y = terms(x)
        return dx @ np.linalg.solve(P, dx) + y @ np.linalg.solve(R, y)

    once, _ = _iterated(x0, P, z, landmark, R, 1)
    mode, _ = _iterated(x0, P, z, landmark, R, 50)
    assert np.abs(gradient(mode)).max() < 1e-4 * np.abs(gradient(once)).max()
    assert cost(mode) < cost(once)
    *_, converged = ekf.correct_iterated(
        x0, P, ekf.innovation(x0, P, z, landmark, SENSOR, R, DEPTH), z, landmark, SENSOR, R,
        DEPTH, 50)
    assert converged


def test_the_iterated_ekf_never_ends_where_the_posterior_is_worse_than_one_pass():
    # Wide priors (a recovery's: metres and tens of degrees): Gauss-Newton may leap to a
    # far point where the one landmark fits as well; the single pass is kept there.
    rng = np.random.default_rng(21)
    R = np.diag([0.05 ** 2, 0.016 ** 2])
    kept = fell_back = 0
    for _ in range(300):
        x0 = np.array([*rng.uniform(-2, 2, 2), rng.uniform(-math.pi, math.pi)])
        P = np.diag([rng.uniform(0.01, 9.0)] * 2 + [rng.uniform(0.01, 1.5) ** 2])
        landmark = tuple(rng.uniform(-4, 4, 2))
        truth = x0 + rng.multivariate_normal(np.zeros(3), P)
        z = range_bearing.expected(truth, landmark, SENSOR, DEPTH)
        if z[0] <= 0.1:
            continue
        observed = ekf.innovation(x0, P, z, landmark, SENSOR, R, DEPTH)
        single, _ = ekf.correct(x0, P, observed, R)
        x, _, searched = ekf.correct_iterated(x0, P, observed, z, landmark, SENSOR, R, DEPTH,
                                              10)
        costs = [ekf.posterior_cost(at, x0, P, z, landmark, SENSOR, R, DEPTH)
                 for at in (x, single)]
        assert costs[0] <= costs[1] * (1 + 1e-9)
        if searched:
            kept += 1
        else:
            fell_back += 1
            np.testing.assert_array_equal(x, single)
    assert kept > 30 and fell_back > 0, (kept, fell_back)


def test_an_iterate_on_the_landmark_leaves_the_single_pass(monkeypatch):
    x, P = np.array([0.0, 0.0, 0.2]), np.diag([0.04, 0.04, 0.05])
    R = np.diag([0.05 ** 2, 0.02 ** 2])
    z, landmark = np.array([2.5, 0.3]), (3.0, 1.0)
    observed = ekf.innovation(x, P, z, landmark, SENSOR, R, DEPTH)
    single = ekf.correct(x, P, observed, R)
    real = ekf.innovation

    def on_the_landmark(at, *args):
        if not np.array_equal(at, x):
            raise ValueError("landmark: at 0 m from the sensor, its bearing is undefined")
        return real(at, *args)

    monkeypatch.setattr(ekf, "innovation", on_the_landmark)
    x_next, P_next, searched = ekf.correct_iterated(x, P, observed, z, landmark, SENSOR, R,
                                                    DEPTH, 10)
    assert not searched
    np.testing.assert_array_equal(x_next, single[0])
    np.testing.assert_array_equal(P_next, single[1])


def test_a_correction_that_fails_is_an_unstable_observation_not_an_error(monkeypatch):
    # An iterate may land on the landmark itself, where its bearing is undefined.
    def on_the_landmark(*_args, **_kwargs):
        raise ValueError("landmark: at 0 m from the sensor, its bearing is undefined")

    monkeypatch.setattr(ekf, "correct_iterated", on_the_landmark)
    localization = LandmarkLocalization(model(iterations=5), [0.0, 0.0, 0.0],
                                        np.eye(3) * 0.01, 0.0)
    before = localization.x.copy()
    outcomes = localization.on_frame(0.0, [Observation(6, 2.2, 0.4)])
    assert [o.verdict for o in outcomes] == ["unstable"]
    np.testing.assert_array_equal(localization.x, before)
    assert localization.counts["unstable"] == 1


def test_a_command_is_driven_after_the_delay_at_the_scaled_speed():
    late = model(odometry_delay=0.25, odometry_scale=(0.5, 0.8))
    localization = LandmarkLocalization(late, [0.0, 0.0, 0.0], np.eye(3) * 0.01, 0.0)
    localization.on_odometry(0.0, 1.0, 0.0)
    localization.on_odometry(1.0, 0.0, 1.0)     # from 1.25 s on: turning in place
    localization.on_odometry(2.0, 0.0, 0.0)     # from 2.25 s on: standing
    # 1 m/s from 0.25 s to 1.25 s, at half the speed: 0.5 m; then 0.8 rad/s to 2 s.
    np.testing.assert_allclose(localization.x, [0.5, 0.0, 0.6], atol=1e-12)
    localization.on_odometry(3.0, 0.0, 0.0)     # turned until 2.25 s
    np.testing.assert_allclose(localization.x, [0.5, 0.0, 0.8], atol=1e-12)


def test_commands_not_yet_driven_are_part_of_the_saved_state():
    late = model(odometry_delay=0.5)
    localization = LandmarkLocalization(late, [0.0, 0.0, 0.0], np.eye(3) * 0.01, 0.0)
    localization.on_odometry(0.0, 1.0, 0.0)
    saved = localization.snapshot()
    localization.on_odometry(0.2, 5.0, 0.0)
    localization.on_frame(2.0, [])
    localization.restore(saved)
    localization.on_frame(2.0, [])
    # only the first command was driven, from 0.5 s to 2 s
    np.testing.assert_allclose(localization.x, [1.5, 0.0, 0.0], atol=1e-12)


def test_without_delay_or_scale_the_filter_is_the_one_before():
    events = [(0.1 * i, (0.2, 0.3 * math.sin(i))) for i in range(40)]
    plain, same = (LandmarkLocalization(m, [0.0, 0.0, 0.0], np.eye(3) * 0.01, 0.0)
                   for m in (model(), model(odometry_delay=0.0, odometry_scale=(1.0, 1.0))))
    for t, (v, w) in events:
        plain.on_odometry(t, v, w)
        same.on_odometry(t, v, w)
        if round(t * 10) % 7 == 6:
            seen = [Observation(6, 2.0, 0.1)]
            plain.on_frame(t, seen)
            same.on_frame(t, seen)
    np.testing.assert_array_equal(plain.x, same.x)
    np.testing.assert_array_equal(plain.P, same.P)


@pytest.mark.parametrize("kind", ["ekf", "ukf"])
def test_a_depth_camera_is_tracked_with_the_depth_model(kind):
    """A robot whose camera reports depth, 3.5 % long, followed by each filter with the
    depth model: it stays within a few centimetres, where the euclidean model errs."""
    rng = np.random.default_rng(3)
    landmarks = {6: (4.0, 1.5), 7: (4.0, -1.5), 8: (6.0, 0.0)}
    points = ukf.SigmaPoints(0.5, 2.0, 0.0) if kind == "ukf" else None
    errors = {}
    for name, ranging in (("depth", DEPTH), ("euclidean", Ranging())):
        filter_model = model(kind=kind, points=points, ranging=ranging, landmarks=landmarks,
                             sensor=SensorPose(0.0, 0.0, 0.0))
        localization = LandmarkLocalization(filter_model, [0.0, 0.0, 0.0],
                                            np.eye(3) * 0.01, 0.0)
        pose = np.zeros(3)
        for step in range(1, 301):
            t = 0.02 * step
            localization.on_odometry(t, 0.2, 0.0)
            pose = pose + [0.2 * 0.02, 0.0, 0.0]
            if step % 10 == 0:
                seen = []
                for key, landmark in landmarks.items():
                    r, b = range_bearing.expected(pose, landmark, SensorPose(0, 0, 0), DEPTH)
                    seen.append(Observation(key, r + rng.normal(0, 0.01),
                                            b + rng.normal(0, 0.005)))
                localization.on_frame(t, seen)
        errors[name] = float(np.hypot(*(localization.x[:2] - pose[:2])))
    assert errors["depth"] < 0.03
    assert errors["euclidean"] > 2 * errors["depth"]


def test_the_parameters_build_the_models():
    values = {**spec_defaults(LANDMARK_MODEL_SPECS), "range_model": "depth",
              "range_scale": 1.035, "ekf.iterations": 10, "odometry_delay": 0.25,
              "odometry_scale": [0.88, 0.95]}
    built = landmark_model(values, {6: (1.0, 2.0)})
    assert built.ranging == DEPTH
    assert (built.iterations, built.odometry_delay, built.odometry_scale) == (10, 0.25,
                                                                              (0.88, 0.95))
    for name, bad, message in (("range_model", "lidar", "range_model"),
                               ("odometry_scale", [1.0], "odometry_scale"),
                               ("odometry_scale", [1.0, 0.0], "odometry_scale"),
                               ("odometry_delay", -0.1, "odometry_delay"),
                               ("odometry_scale", [1.0, 11.0], "odometry_scale"),
                               ("ekf.iterations", 0, "ekf.iterations")):
        with pytest.raises(ValueError, match=message):
            landmark_model({**values, name: bad}, {6: (1.0, 2.0)})


ROBOTS_FILE = Path(__file__).resolve().parents[2] / "msgs_config" / "robots" / "utias_mrclam.yaml"
DATASET = Path(__file__).resolve().parents[3] / "shared" / "data" / "utias" / "MRCLAM_Dataset7"


def _shipped_figures() -> dict:
    values = read_node_parameters(ROBOTS_FILE.read_text(encoding="utf-8"), "/ekf_localizer")
    return {name: value for name, value in values.items()
            if name in spec_defaults(LANDMARK_MODEL_SPECS)}


def test_the_shipped_robot_file_builds_a_model():
    figures = _shipped_figures()
    built = landmark_model({**spec_defaults(LANDMARK_MODEL_SPECS), **figures}, {6: (0.0, 1.0)})
    assert built.ranging.kind == "depth" and built.odometry_delay > 0


@pytest.mark.skipif(not DATASET.is_dir(), reason="the UTIAS dataset is not in ../shared/data")
def test_the_shipped_figures_are_what_the_calibration_derives():
    from bench.landmarks.utias_calibration import calibrate
    from estimation_nodes.tools.importers.utias import read_run

    derived = calibrate([read_run(DATASET, robot) for robot in (1, 2, 3)])
    shipped = _shipped_figures()
    for name, value in derived.items():
        if isinstance(value, str):
            assert shipped[name] == value, name
        else:
            np.testing.assert_allclose(shipped[name], value, rtol=2e-3, atol=1e-6,
                                       err_msg=name)


def random_motion(rng, n: int = 3):
    """A state of ``n`` (the pose, and a range scale near 1 for 4), a covariance, a step."""
    x = np.append(rng.normal(0, 2, 3), 1.0 + rng.normal(0, 0.05, n - 3))
    x[2] = wrap(x[2])
    A = rng.normal(0, 0.3, (n, n))
    P = A @ A.T + np.eye(n) * 1e-3
    return x, P, rng.normal(0, 0.5), rng.normal(0, 1.0), rng.uniform(0, 0.2)


@pytest.mark.parametrize("n", [3, 4])
def test_the_written_out_prediction_is_the_matrix_one(n):
    rng = np.random.default_rng(7)
    for _ in range(200):
        x, P, v, w, dt = random_motion(rng, n)
        fast = ekf.predict(x, P, v, w, dt, NOISE)
        matrices = ekf.predict_by_matrices(x, P, v, w, dt, NOISE)
        np.testing.assert_allclose(fast[0], matrices[0], rtol=0, atol=1e-15)
        np.testing.assert_allclose(fast[1], matrices[1], rtol=1e-13, atol=1e-15)
    for bad in (math.nan, math.inf):
        with pytest.raises(ValueError, match="v"):
            ekf.predict(x, P, bad, 0.0, 0.1, NOISE)
    with pytest.raises(ValueError, match="dt"):
        ekf.predict(x, P, 0.1, 0.0, -0.1, NOISE)


@pytest.mark.skipif(load_kernels("estimation_nodes.core.kalman.compiled") is None,
                    reason="numba does not import here")
@pytest.mark.parametrize("n", [3, 4])
def test_the_compiled_unscented_prediction_is_numpys(n):
    rng = np.random.default_rng(8)
    points = ukf.SigmaPoints(0.5, 2.0, 0.0, n=n)
    for _ in range(200):
        x, P, v, w, dt = random_motion(rng, n)
        compiled = ukf.predict(x, P, v, w, dt, NOISE, points)
        reference = ukf.predict_numpy(x, P, v, w, dt, NOISE, points)
        np.testing.assert_allclose(compiled[0], reference[0], rtol=0, atol=1e-13)
        np.testing.assert_allclose(compiled[1], reference[1], rtol=1e-12, atol=1e-15)
    # no Cholesky factor: numpy's error, from either path
    for compiled in (True, False):
        with pytest.raises(np.linalg.LinAlgError):
            ukf.predict(x, -np.eye(n), 0.1, 0.0, 0.1, NOISE, points, compiled)


def test_a_new_model_brings_its_gate():
    # An observation 3 sigma off in bearing, NIS about 9: inside a 0.999 gate (13.8), outside
    # a 0.95 one (5.99). The gate follows the model the filter is given.
    localization = LandmarkLocalization(model(gate_probability=0.999), [0.0, 0.0, 0.0],
                                        np.eye(3) * 1e-6, 0.0)
    r, b = range_bearing.expected(localization.x, (2.0, 1.0), SENSOR)
    far = Observation(6, r, b + 3 * 0.02)
    assert [o.verdict for o in localization.on_frame(0.0, [far])] == ["used"]
    localization = LandmarkLocalization(model(gate_probability=0.999), [0.0, 0.0, 0.0],
                                        np.eye(3) * 1e-6, 0.0)
    localization.model = model(gate_probability=0.95)
    assert [o.verdict for o in localization.on_frame(0.0, [far])] == ["gated"]


# --- the range's scale as a fourth state -------------------------------------------------

@pytest.mark.parametrize("ranging", [Ranging(), DEPTH])
def test_the_jacobian_with_the_scale_state_is_its_derivative(ranging):
    x = np.array([1.0, 2.0, 0.7, 1.04])
    for landmark in [(2.0, 1.0), (-1.5, 2.5), (0.5, -2.0)]:
        expected = numeric_jacobian(
            lambda s, lm=landmark: range_bearing.expected(s, lm, SENSOR, ranging), x)
        H = range_bearing.jacobian(x, landmark, SENSOR, ranging)
        assert H.shape == (2, 4)
        np.testing.assert_allclose(H, expected, atol=1e-7)
    # the state's scale, not the model's, is the one seen
    assert range_bearing.expected(x, (2.0, 1.0), SENSOR, ranging)[0] == pytest.approx(
        1.04 / ranging.scale * range_bearing.expected(x[:3], (2.0, 1.0), SENSOR, ranging)[0])


def test_the_prediction_with_the_scale_state_moves_the_pose_and_keeps_the_scale():
    rng = np.random.default_rng(9)
    points = ukf.SigmaPoints(0.5, 2.0, 0.0, n=4)
    for _ in range(100):
        x, P, v, w, dt = random_motion(rng, 4)
        fast = ekf.predict(x, P, v, w, dt, NOISE)
        # the pose's block is the three-state prediction's; the scale and its variance stay
        three = ekf.predict(x[:3], P[:3, :3], v, w, dt, NOISE)
        np.testing.assert_allclose(fast[1][:3, :3], three[1], rtol=1e-13, atol=1e-15)
        assert fast[0][3] == x[3] and fast[1][3, 3] == P[3, 3]
        unscented = ukf.predict(x, P, v, w, dt, NOISE, points)
        assert unscented[0][3] == pytest.approx(x[3], abs=1e-12)
        assert unscented[1][3, 3] == pytest.approx(P[3, 3], rel=1e-9)


def _scaled_run(kind: str, scale_std: float, true_scale: float = 1.06):
    """A robot driving a loop among four landmarks, its camera ranging ``true_scale``
    times the depth while the model's prior says 1.0."""
    rng = np.random.default_rng(11)
    landmarks = {6: (3.0, 1.5), 7: (3.0, -1.5), 8: (-1.0, 2.5), 9: (5.0, 0.5)}
    n = 4 if scale_std > 0 else 3
    points = ukf.SigmaPoints(0.5, 2.0, 0.0, n=n) if kind == "ukf" else None
    filter_model = model(kind=kind, points=points, ranging=Ranging("depth", 1.0),
                         landmarks=landmarks, sensor=SensorPose(0.0, 0.0, 0.0),
                         range_std=0.005, range_std_per_m=0.0, bearing_std=0.005,
                         range_scale_std=scale_std)
    localization = LandmarkLocalization(filter_model, [0.0, 0.0, 0.0], np.eye(3) * 0.01, 0.0)
    truth = Ranging("depth", true_scale)
    pose = np.zeros(3)
    for step in range(1, 1501):
        t = 0.02 * step
        localization.on_odometry(t, 0.3, 0.25)
        pose = unicycle.move(pose, 0.3, 0.25, 0.02)
        if step % 10 == 0:
            seen = []
            for key, landmark in landmarks.items():
                r, b = range_bearing.expected(pose, landmark, SensorPose(0, 0, 0), truth)
                if r > 0.3 and abs(b) < 1.2:                   # in front of the camera
                    seen.append(Observation(key, r + rng.normal(0, 0.005),
                                            b + rng.normal(0, 0.005)))
            localization.on_frame(t, seen)
    return localization, pose


@pytest.mark.parametrize("kind", ["ekf", "ukf"])
def test_a_wrong_range_scale_is_learned_as_the_fourth_state(kind):
    """A camera 6% long, a prior of 1.0: fixed, the scale pulls the pose off; estimated,
    the filter finds it, and the pose with it."""
    fixed, pose = _scaled_run(kind, 0.0)
    learned, _ = _scaled_run(kind, 0.1)
    scale, scale_std = learned.range_scale
    assert abs(scale - 1.06) < 3 * scale_std < 0.01
    assert fixed.range_scale == (1.0, 0.0)
    error = {name: float(np.hypot(*(loc.pose[:2] - pose[:2])))
             for name, loc in (("fixed", fixed), ("learned", learned))}
    assert error["learned"] < 0.02 < error["fixed"]
    assert learned.pose.shape == (3,) and learned.pose_covariance.shape == (3, 3)


def test_the_scale_state_needs_sigma_points_of_its_size_and_stays_fixed():
    with pytest.raises(ValueError, match="sigma points"):
        model(kind="ukf", points=ukf.SigmaPoints(0.5, 2.0, 0.0), range_scale_std=0.05)
    for bad in (-0.1, math.nan, 0.3):
        with pytest.raises(ValueError, match="range_scale_std"):
            model(range_scale_std=bad)
    localization = LandmarkLocalization(model(range_scale_std=0.05), [0.0, 0.0, 0.0],
                                        np.eye(3) * 0.01, 0.0)
    assert localization.x.tolist() == [0.0, 0.0, 0.0, 1.0]
    assert localization.P[3, 3] == pytest.approx(0.05 ** 2)
    with pytest.raises(ValueError, match="fixed at the start"):
        localization.model = model()
