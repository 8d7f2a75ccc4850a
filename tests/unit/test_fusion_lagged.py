"""smooth_lagged_data: a late measurement put in its place gives what the filter gives
over the same events in time order, bit for bit; without the history, or older than it,
it is corrected at the filter's time, as the peer does."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from estimation_nodes.core.fusion import state
from estimation_nodes.core.fusion.filter import FusionFilter, FusionSettings
from estimation_nodes.core.fusion.steps import Measurement
from estimation_nodes.params.fusion import FusionConfigError, fusion_config

MS = 1_000_000
#: Long enough that the periodic step never predicts on its own, unless a test says so.
NO_TIMEOUT = 10**15
TWIST = (state.VX, state.VY, state.VYAW)
POSE = (state.X, state.Y, state.YAW)


def settings(kind: str = "ekf", history_s: float | None = 10.0, **changes) -> FusionSettings:
    base = FusionSettings(kind=kind, sensor_timeout_ns=NO_TIMEOUT,
                          history_ns=None if history_s is None else round(history_s * 1e9),
                          initial_covariance=np.eye(15) * 1e-2)
    return dataclasses.replace(base, **changes)


def readings(count: int, seed: int) -> list[Measurement]:
    """A robot's twist (every 20 ms) and pose fixes (every 5th), with noise and a
    Mahalanobis threshold that rejects some of them."""
    rng = np.random.default_rng(seed)
    measurements = []
    for k in range(count):
        z = np.zeros(15)
        t_ns = k * 20 * MS + int(rng.integers(0, 5 * MS))
        if k % 5 == 4:
            z[list(POSE)] = [0.02 * k, 0.01 * k, 0.005 * k] + rng.normal(0.0, 0.05, 3)
            measurements.append(Measurement(t_ns, z, np.eye(15) * 0.01, POSE, 3.0, "pose0"))
        else:
            z[list(TWIST)] = [1.0, 0.5, 0.25] + rng.normal(0.0, 0.1, 3)
            measurements.append(Measurement(t_ns, z, np.eye(15) * 0.01, TWIST, 2.0,
                                            "odom0_twist"))
    return measurements


def in_time_order(measurements: list[Measurement], kind: str) -> FusionFilter:
    reference = FusionFilter(settings(kind, history_s=None))
    for measurement in sorted(measurements, key=lambda m: m.stamp_ns):
        reference.process(measurement)
    return reference


def delivered_late(measurements: list[Measurement], settings_: FusionSettings, seed: int
                   ) -> FusionFilter:
    """Each measurement reaches the filter up to 100 ms late, and the periodic step runs
    every 10 ms in between."""
    rng = np.random.default_rng(seed)
    arrivals = sorted((m.stamp_ns + int(rng.integers(0, 100 * MS)), i)
                      for i, m in enumerate(measurements))
    fusion = FusionFilter(settings_)
    now = 0
    for arrival_ns, i in arrivals:
        while now < arrival_ns:
            fusion.update(now)
            now += 10 * MS
        fusion.enqueue(measurements[i])
    fusion.update(max(m.stamp_ns for m in measurements))
    return fusion


@pytest.mark.parametrize("kind", ["ekf", "ukf"])
@pytest.mark.parametrize("seed", [1, 2])
def test_late_measurements_give_what_the_same_ones_give_in_time_order(kind, seed):
    measurements = readings(150, seed)
    smoothed = delivered_late(measurements, settings(kind), seed)
    reference = in_time_order(measurements, kind)
    assert sum(smoothed.counts.smoothed.values()) > 20
    assert sum(reference.counts.rejected.values()) > 0
    # Each measurement counted once, as what it was in the end: a replay that took one
    # rejected on arrival (or the reverse) moved its count.
    assert smoothed.counts.applied == reference.counts.applied
    assert smoothed.counts.rejected == reference.counts.rejected
    np.testing.assert_array_equal(smoothed.x, reference.x)
    np.testing.assert_array_equal(smoothed.p, reference.p)
    assert smoothed.last_time_ns == reference.last_time_ns
    # Without the history the same arrivals end elsewhere: the test can tell.
    unsmoothed = delivered_late(measurements, settings(kind, history_s=None), seed)
    assert np.max(np.abs(unsmoothed.x - reference.x)) > 1e-3
    assert not unsmoothed.counts.smoothed


def reading(t_ms: int, vx: float) -> Measurement:
    z = np.zeros(15)
    z[state.VX] = vx
    return Measurement(t_ms * MS, z, np.eye(15) * 0.01, (state.VX,), source="odom0_twist")


def test_a_periodic_prediction_is_an_event_of_its_time():
    """With a sensor timeout the periodic step predicts to now; a measurement older than
    that prediction goes before it, and the prediction runs again from it."""
    fusion = FusionFilter(settings(sensor_timeout_ns=50 * MS))
    fusion.enqueue(reading(0, 1.0))
    fusion.update(0)
    fusion.update(100 * MS)                       # a timeout: predicts to 100 ms
    assert fusion.last_time_ns == 100 * MS
    fusion.enqueue(reading(60, 2.0))
    fusion.update(110 * MS)
    reference = FusionFilter(settings(history_s=None))
    reference.process(reading(0, 1.0))
    reference.process(reading(60, 2.0))
    reference.predict(40 * MS)
    np.testing.assert_array_equal(fusion.x, reference.x)
    np.testing.assert_array_equal(fusion.p, reference.p)
    assert fusion.last_time_ns == 100 * MS
    assert fusion.counts.smoothed == {"odom0_twist": 1}


def test_a_command_is_an_event_of_its_time():
    """use_control: a measurement older than a command moves the state the command's
    term then starts from."""
    config = fusion_config({"odom0": "odom", "use_control": True, "smooth_lagged_data": True,
                            "history_length": 1.0, "sensor_timeout": 1e6,
                            "control_config": [True] + [False] * 5})
    fusion = FusionFilter(config.settings)
    command = (1.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    fusion.enqueue(reading(0, 0.0))
    fusion.update(0)
    fusion.command(command, 200 * MS)
    fusion.enqueue(reading(100, 0.5))             # older than the command
    fusion.enqueue(reading(300, 0.6))
    fusion.update(300 * MS)
    reference = FusionFilter(dataclasses.replace(config.settings, history_ns=None))
    reference.process(reading(0, 0.0))
    reference.process(reading(100, 0.5))
    reference.command(command, 200 * MS)
    reference.process(reading(300, 0.6))
    np.testing.assert_array_equal(fusion.x, reference.x)
    np.testing.assert_array_equal(fusion.p, reference.p)


def test_a_measurement_older_than_the_history_is_corrected_at_the_filters_time():
    measurements = [reading(t, 1.0) for t in range(0, 1000, 20)]
    late = reading(500, 3.0)
    fusion = FusionFilter(settings(history_s=0.1))
    plain = FusionFilter(settings(history_s=None))
    for filter_ in (fusion, plain):
        for measurement in measurements:
            filter_.enqueue(measurement)
        filter_.update(1000 * MS)
        filter_.enqueue(late)
        filter_.update(1000 * MS)
    assert fusion.counts.beyond_history == {"odom0_twist": 1}
    assert not fusion.counts.smoothed
    np.testing.assert_array_equal(fusion.x, plain.x)
    np.testing.assert_array_equal(fusion.p, plain.p)


@pytest.mark.parametrize("kind", ["ekf", "ukf"])
def test_set_pose_forgets_the_history(kind):
    fusion = FusionFilter(settings(kind))
    plain = FusionFilter(settings(kind, history_s=None))
    pose = Measurement(50 * MS, np.zeros(15), np.eye(15) * 0.01, POSE)
    for filter_ in (fusion, plain):
        for t in (0, 20, 40):
            filter_.enqueue(reading(t, 1.0))
        filter_.update(40 * MS)
        filter_.predict(5 * MS)                   # the UKF's propagated points: stale now
        filter_.set_pose(pose, 50 * MS)
        filter_.enqueue(reading(30, 5.0))         # before the pose: nothing to go back to
        filter_.update(60 * MS)                   # corrected at the pose's time
    assert fusion.counts.before_floor == {"odom0_twist": 1}
    assert fusion.x[state.VX] > 0.0               # it moved the estimate
    assert fusion.p[state.VX, state.VX] > 0.0
    np.testing.assert_array_equal(fusion.x, plain.x)
    np.testing.assert_array_equal(fusion.p, plain.p)
    assert fusion.last_time_ns == 50 * MS


def test_the_peers_parameters_and_their_warnings():
    smoothing = fusion_config({"smooth_lagged_data": True, "history_length": 0.5})
    assert smoothing.settings.history_ns == 500_000_000 and not smoothing.notes
    assert not {"smooth_lagged_data", "history_length"} & set(smoothing.unsupported)
    negative = fusion_config({"smooth_lagged_data": True, "history_length": -0.5})
    assert negative.settings.history_ns == 500_000_000
    assert negative.notes == ("Negative history interval of -0.5 specified. Absolute value "
                              "will be assumed.",)
    unused = fusion_config({"history_length": 2.0})
    assert unused.settings.history_ns is None
    assert "Lagged data will not be smoothed" in unused.notes[0]
    assert fusion_config({"smooth_lagged_data": True}).settings.history_ns == 0
    for bad in (float("nan"), "long", True):
        with pytest.raises(FusionConfigError, match="history_length: expected a finite time"):
            fusion_config({"smooth_lagged_data": True, "history_length": bad})
    with pytest.raises(FusionConfigError, match="smooth_lagged_data: expected true or false"):
        fusion_config({"smooth_lagged_data": "false"})


def test_a_pause_drops_the_queue_and_nothing_goes_back_before_it():
    """The peer's toggle off: what was queued is dropped and returned, the filter's time is
    the pause's; with the history, a measurement from before the pause is not put back."""
    fusion = FusionFilter(settings())
    fusion.enqueue(reading(0, 1.0))
    fusion.update(0)
    fusion.enqueue(reading(20, 2.0))
    assert [m.stamp_ns for m in fusion.pause(50 * MS)] == [20 * MS]
    assert fusion.queued == 0 and fusion.last_time_ns == 50 * MS
    x = fusion.x.copy()
    fusion.enqueue(reading(30, 5.0))
    fusion.update(60 * MS)
    assert fusion.counts.before_floor == {"odom0_twist": 1}
    assert fusion.x[state.VX] > x[state.VX] and fusion.last_time_ns == 50 * MS
