"""The landmark EKF and UKF: their models' Jacobians, equality with filterpy 2.0 given the
same models and events, and the event rules (unknown ids, the gate and its recovery).

filterpy is wired here by the test's own code: its ExtendedKalmanFilter with the
Jacobians passed in, its UnscentedKalmanFilter with MerweScaledSigmaPoints, angle
means and wrapped residuals. Only the motion and measurement functions are ours.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from filterpy.kalman import ExtendedKalmanFilter, MerweScaledSigmaPoints, UnscentedKalmanFilter

from estimation_nodes.core.kalman import range_bearing, ukf, unicycle
from estimation_nodes.core.kalman.landmarks import (
    LandmarkLocalization,
    LandmarkModel,
    Observation,
    chi_square_2_quantile,
)
from estimation_nodes.core.kalman.range_bearing import EUCLIDEAN, Ranging, SensorPose
from estimation_nodes.core.kalman.unicycle import UnicycleNoise, wrap

DATASET = Path(__file__).resolve().parents[3] / "shared" / "data" / "utias" / "MRCLAM_Dataset7"
NOISE = UnicycleNoise(4e-4, 3e-3, 1e-6, 1e-4, 1.2e-2, 1.2e-3)
SENSOR = SensorPose(0.05, -0.02, 0.03)
R = np.diag([0.12 ** 2, 0.027 ** 2])
LANDMARKS = {6: (2.0, 1.0), 7: (-1.5, 2.5), 8: (0.5, -2.0), 9: (3.0, -1.0)}


def numeric_jacobian(function, x, residual=np.subtract):
    columns = []
    for i in range(x.size):
        step = np.zeros_like(x)
        step[i] = 1e-6
        columns.append(residual(function(x + step), function(x - step)) / 2e-6)
    return np.column_stack(columns)


@pytest.mark.parametrize("pose", [(1.0, 2.0, 0.7), (-0.3, 0.4, -2.9), (0.0, 0.0, math.pi - 1e-3)])
def test_the_range_bearing_jacobian_is_the_derivative(pose):
    x = np.array(pose)
    for landmark in LANDMARKS.values():
        def seen(s, lm=landmark):
            return range_bearing.expected(s, lm, SENSOR)

        expected = numeric_jacobian(seen, x, range_bearing.residual)
        np.testing.assert_allclose(range_bearing.jacobian(x, landmark, SENSOR), expected,
                                   atol=1e-7)


@pytest.mark.parametrize("v, w", [(0.3, 0.5), (0.2, 0.0), (0.0, -1.0), (-0.1, 0.2)])
def test_the_unicycle_jacobian_is_the_derivative(v, w):
    x = np.array([1.0, -2.0, 0.4])
    F, G = unicycle.jacobians(x, v, w, 0.1)
    np.testing.assert_allclose(F, numeric_jacobian(lambda s: unicycle.move(s, v, w, 0.1), x),
                               atol=1e-7)

    def by_step(u):
        # move by distance d and turn phi: v = d / dt, w = phi / dt
        return unicycle.move(x, u[0] / 0.1, u[1] / 0.1, 0.1)

    np.testing.assert_allclose(G, numeric_jacobian(by_step, np.array([v * 0.1, w * 0.1])),
                               atol=1e-7)


def test_the_gate_is_the_chi_square_quantile():
    # chi-square with 2 dof: P(X <= q) = 1 - exp(-q / 2); the 95% point is 5.991.
    assert chi_square_2_quantile(0.95) == pytest.approx(5.991464547, rel=1e-9)
    assert chi_square_2_quantile(1.0) == math.inf


def simulated_events(seed: int, seconds: float = 60.0):
    """A unicycle wandering among LANDMARKS: odometry at 50 Hz (twist), frames at 3 Hz
    (noisy range and bearing of the landmarks in front), both stamped."""
    rng = np.random.default_rng(seed)
    pose = np.array([0.0, 0.0, 0.3])
    events, t = [], 0.0
    v, w = 0.2, 0.1
    for step in range(int(seconds * 50)):
        if step % 50 == 0:
            v, w = rng.uniform(0.05, 0.3), rng.uniform(-0.6, 0.6)
        events.append((t, "odom", (v, w)))
        pose = unicycle.move(pose, v + rng.normal(0, 0.02), w + rng.normal(0, 0.05), 0.02)
        t = round(t + 0.02, 9)
        if step % 17 == 16:
            seen = []
            for key, landmark in LANDMARKS.items():
                r, b = range_bearing.expected(pose, landmark, SENSOR)
                if abs(b) < 1.0:
                    seen.append(Observation(key, r + rng.normal(0, 0.12),
                                            wrap(b + rng.normal(0, 0.027))))
            events.append((t, "frame", seen))
    return events


def dataset_events(robot: int, seconds: float):
    from estimation_nodes.tools.importers.utias import read_run

    run = read_run(DATASET, robot)
    start = run.odometry[0, 0]
    events = [(t - start, "odom", (v, w)) for t, v, w in run.odometry if t - start <= seconds]
    events += [(t - start, "frame", [Observation(int(s), r, b) for _, s, r, b in rows])
               for t, rows in run.frames() if t - start <= seconds]
    events.sort(key=lambda e: (e[0], e[1] == "frame"))
    return events, run.landmarks, run.truth[0, 1:]


def ours(kind, events, landmarks, x0, ranging=EUCLIDEAN, scale_std=0.0):
    points = ukf.SigmaPoints(0.5, 2.0, 0.0, n=4 if scale_std else 3) if kind == "ukf" else None
    model = LandmarkModel(kind, NOISE, 0.12, 0.0, 0.027, SENSOR, landmarks, 1.0, 5.0, (1.0, 0.5),
                          points, ranging, range_scale_std=scale_std)
    localization = LandmarkLocalization(model, x0, np.diag([0.04, 0.04, 0.02]), 0.0)
    for t, kind_, data in events:
        if kind_ == "odom":
            localization.on_odometry(t, *data)
        else:
            localization.on_frame(t, data)
    return localization.x, localization.P


class NonlinearEKF(ExtendedKalmanFilter):
    """filterpy's EKF with the unicycle as its motion (predict_x is its documented hook)."""

    twist = (0.0, 0.0)
    dt = 0.0

    def predict_x(self, u=0):
        self.x = np.append(unicycle.move(self.x, *self.twist, self.dt), self.x[3:])


def start(x0, ranging, scale_std):
    """The initial state and covariance: the pose, and with ``scale_std`` the range's scale
    as a fourth state (its prior: the ranging's scale, that std)."""
    x = np.array(x0, float)
    P = np.diag([0.04, 0.04, 0.02])
    if not scale_std:
        return x, P
    return np.append(x, ranging.scale), np.diag([0.04, 0.04, 0.02, scale_std ** 2])


def padded(matrix, n):
    """``matrix`` (the pose's block) in the top left of an n x n one, the rest zero."""
    out = np.zeros((n, n))
    out[:matrix.shape[0], :matrix.shape[1]] = matrix
    return out


def filterpy_nonlinear_ekf(events, landmarks, x0, ranging=EUCLIDEAN, scale_std=0.0):
    n = 4 if scale_std else 3
    f = NonlinearEKF(dim_x=n, dim_z=2)
    (f.x, f.P), f.R = start(x0, ranging, scale_std), R
    time = 0.0
    for t, kind, data in events:
        dt = t - time
        if dt > 0:
            v, w = f.twist
            F, G = unicycle.jacobians(f.x, v, w, dt)
            var_d, var_phi = NOISE.variances(v * dt, w * dt, dt)
            F = padded(F, n) + np.diag([0.0] * 3 + [1.0] * (n - 3))  # the scale stays
            f.F, f.Q, f.dt = F, padded(G @ np.diag([var_d, var_phi]) @ G.T, n), dt
            f.predict()
            time = t
        if kind == "odom":
            f.twist = data
            continue
        for seen in data:
            landmark = landmarks[seen.landmark]
            f.update(np.array([seen.range, seen.bearing]),
                     lambda s, lm=landmark: range_bearing.jacobian(s, lm, SENSOR, ranging),
                     lambda s, lm=landmark: range_bearing.expected(s, lm, SENSOR, ranging),
                     residual=range_bearing.residual)
            f.x[2] = wrap(f.x[2])
    return f.x, f.P


def angle_mean(points, weights, angle):
    mean = weights @ points
    mean[angle] = math.atan2(weights @ np.sin(points[:, angle]),
                             weights @ np.cos(points[:, angle]))
    return mean


def filterpy_ukf(events, landmarks, x0, ranging=EUCLIDEAN, scale_std=0.0):
    n = 4 if scale_std else 3

    def subtract(a, b):
        return np.r_[a[:2] - b[:2], wrap(a[2] - b[2]), a[3:] - b[3:]]

    points = MerweScaledSigmaPoints(n, alpha=0.5, beta=2.0, kappa=0.0, subtract=subtract)
    state = {"twist": (0.0, 0.0)}
    f = UnscentedKalmanFilter(
        dim_x=n, dim_z=2, dt=0.0, points=points,
        fx=lambda s, dt: np.append(unicycle.move(s, *state["twist"], dt), s[3:]),
        hx=lambda s, lm: range_bearing.expected(s, lm, SENSOR, ranging),
        x_mean_fn=lambda p, wm: angle_mean(p, wm, 2),
        z_mean_fn=lambda p, wm: angle_mean(p, wm, 1),
        residual_x=subtract, residual_z=range_bearing.residual)
    (f.x, f.P), f.R = start(x0, ranging, scale_std), R
    time = 0.0
    for t, kind, data in events:
        dt = t - time
        if dt > 0:
            f.Q = padded(unicycle.process_noise(f.x, *state["twist"], dt, NOISE), n)
            f.predict(dt=dt)
            time = t
        if kind == "odom":
            state["twist"] = data
            continue
        for seen in data:
            # filterpy reuses the sigma points of its last predict for every update;
            # ours are drawn from the estimate each observation starts from.
            f.sigmas_f = points.sigma_points(f.x, f.P)
            f.update(np.array([seen.range, seen.bearing]), lm=landmarks[seen.landmark])
            f.x[2] = wrap(f.x[2])
    return f.x, f.P


@pytest.mark.parametrize("seed", [1, 2])
def test_the_ekf_equals_filterpy_on_a_simulated_run(seed):
    events = simulated_events(seed)
    x, P = ours("ekf", events, LANDMARKS, (0.0, 0.0, 0.3))
    fx, fP = filterpy_nonlinear_ekf(events, LANDMARKS, (0.0, 0.0, 0.3))
    np.testing.assert_allclose(x, fx, atol=1e-9)
    np.testing.assert_allclose(P, fP, atol=1e-9)


@pytest.mark.parametrize("seed", [1, 2])
def test_the_ukf_equals_filterpy_on_a_simulated_run(seed):
    events = simulated_events(seed)
    x, P = ours("ukf", events, LANDMARKS, (0.0, 0.0, 0.3))
    fx, fP = filterpy_ukf(events, LANDMARKS, (0.0, 0.0, 0.3))
    np.testing.assert_allclose(x, fx, atol=1e-9)
    np.testing.assert_allclose(P, fP, atol=1e-9)


@pytest.mark.parametrize("kind", ["ekf", "ukf"])
def test_the_filters_with_the_scale_state_equal_filterpy_on_a_simulated_run(kind):
    events = simulated_events(3)
    ranging = Ranging("euclidean", 0.98)         # the model's prior; the camera is exact
    x, P = ours(kind, events, LANDMARKS, (0.0, 0.0, 0.3), ranging, scale_std=0.05)
    reference = filterpy_nonlinear_ekf if kind == "ekf" else filterpy_ukf
    fx, fP = reference(events, LANDMARKS, (0.0, 0.0, 0.3), ranging, scale_std=0.05)
    assert x.size == 4
    np.testing.assert_allclose(x, fx, atol=1e-9)
    np.testing.assert_allclose(P, fP, atol=1e-9)


@pytest.mark.skipif(not DATASET.is_dir(), reason=f"the UTIAS dataset is not at {DATASET}")
@pytest.mark.parametrize("ranging, scale_std", [(EUCLIDEAN, 0.0), (Ranging("depth", 1.035), 0.0),
                                                (Ranging("depth", 1.035), 0.015)],
                         ids=["distance", "depth", "depth, scale estimated"])
@pytest.mark.parametrize("kind", ["ekf", "ukf"])
@pytest.mark.timeout(360)     # 50 s alone; several times that with both cores busy
def test_both_filters_equal_filterpy_over_a_whole_real_run(kind, ranging, scale_std):
    events, landmarks, x0 = dataset_events(1, seconds=1e9)
    x, P = ours(kind, events, landmarks, x0, ranging, scale_std)
    reference = filterpy_nonlinear_ekf if kind == "ekf" else filterpy_ukf
    fx, fP = reference(events, landmarks, x0, ranging, scale_std)
    np.testing.assert_allclose(x, fx, atol=1e-9)
    np.testing.assert_allclose(P, fP, atol=1e-9)


def model(kind="ekf", gate_probability=0.99, recovery_time=3.0):
    points = ukf.SigmaPoints(0.5, 2.0, 0.0) if kind == "ukf" else None
    return LandmarkModel(kind, NOISE, 0.12, 0.0, 0.027, SENSOR, LANDMARKS, gate_probability,
                         recovery_time, (1.0, 0.5), points)


def run(localization, events):
    outcomes = []
    for t, kind, data in events:
        if kind == "odom":
            localization.on_odometry(t, *data)
        else:
            outcomes += localization.on_frame(t, data)
    return outcomes


def final_error(events, localization, seed):
    truth = simulated_truth(seed)
    return float(np.hypot(*(localization.x[:2] - truth[:2])))


def simulated_truth(seed: int, seconds: float = 60.0):
    """The true final pose of ``simulated_events(seed, seconds)`` (the same draws)."""
    rng = np.random.default_rng(seed)
    pose = np.array([0.0, 0.0, 0.3])
    v, w = 0.2, 0.1
    for step in range(int(seconds * 50)):
        if step % 50 == 0:
            v, w = rng.uniform(0.05, 0.3), rng.uniform(-0.6, 0.6)
        pose = unicycle.move(pose, v + rng.normal(0, 0.02), w + rng.normal(0, 0.05), 0.02)
        if step % 17 == 16:
            for landmark in LANDMARKS.values():
                if abs(range_bearing.expected(pose, landmark, SENSOR)[1]) < 1.0:
                    rng.normal(0, 0.12), rng.normal(0, 0.027)
    return pose


@pytest.mark.parametrize("kind", ["ekf", "ukf"])
def test_a_filter_started_in_the_right_place_tracks_the_robot(kind):
    localization = LandmarkLocalization(model(kind), (0.0, 0.0, 0.3),
                                        np.diag([0.01, 0.01, 0.01]), 0.0)
    outcomes = run(localization, simulated_events(3))
    assert {o.verdict for o in outcomes} <= {"used", "gated"}
    assert localization.counts["used"] > 0.9 * len(outcomes)
    assert final_error(None, localization, 3) < 0.15


@pytest.mark.parametrize("kind", ["ekf", "ukf"])
def test_a_lost_filter_recovers_after_recovery_time_instead_of_gating_for_ever(kind):
    # Started 2 m and 90 degrees off with a confident covariance: every true observation
    # is implausible to it, so the gate alone would reject all of them for ever.
    wrong = (2.0, -1.5, 0.3 + math.pi / 2)
    gated_only = LandmarkLocalization(model(kind, recovery_time=1e6), wrong,
                                      np.diag([1e-4, 1e-4, 1e-4]), 0.0)
    run(gated_only, simulated_events(3))
    assert final_error(None, gated_only, 3) > 1.0
    recovering = LandmarkLocalization(model(kind, recovery_time=3.0), wrong,
                                      np.diag([1e-4, 1e-4, 1e-4]), 0.0)
    # one landmark per frame: no frame places the robot by itself (test_relocalization.py),
    # the widening covariance alone must bring the observations back
    run(recovering, [(t, event, data[:1] if event == "frame" else data)
                     for t, event, data in simulated_events(3)])
    assert recovering.counts["recoveries"] >= 1 and recovering.counts["recovered"] >= 1
    assert recovering.counts["relocalized"] == 0
    assert not recovering.lost
    # a quarter of the observations of the runs above: back near the robot, not as close
    assert final_error(None, recovering, 3) < 0.4


def test_unknown_ids_and_invalid_observations_are_counted_and_change_nothing():
    localization = LandmarkLocalization(model(), (0.0, 0.0, 0.3), np.eye(3) * 0.01, 0.0)
    before = (localization.x.copy(), localization.P.copy())
    outcomes = localization.on_frame(0.0, [Observation(99, 2.0, 0.1),
                                           Observation(6, math.nan, 0.1),
                                           Observation(6, -1.0, 0.1),
                                           Observation(6, 2.0, math.inf)])
    assert [o.verdict for o in outcomes] == ["unknown", "invalid", "invalid", "invalid"]
    assert localization.counts == {"unknown": 1, "invalid": 3}
    np.testing.assert_array_equal(localization.x, before[0])
    np.testing.assert_array_equal(localization.P, before[1])


@pytest.mark.parametrize("bad", [(math.nan, 0.0), (0.1, math.inf)])
def test_non_finite_odometry_is_refused_with_the_state_unchanged(bad):
    localization = LandmarkLocalization(model(), (0.0, 0.0, 0.3), np.eye(3) * 0.01, 0.0)
    localization.on_odometry(0.0, 0.2, 0.0)
    with pytest.raises(ValueError, match="odometry"):
        localization.on_odometry(1.0, *bad)
    assert localization.t == 0.0 and localization.twist == (0.2, 0.0)
