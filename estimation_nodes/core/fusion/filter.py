"""The fusion filter as robot_localization's node runs it, with no ROS in it.

- The first measurement initializes: the entries it measures take its values and
  covariance (variances floored as a correction floors them), the others keep the
  initial state and ``initial_estimate_covariance``.
- Later ones predict from the last measurement's time to theirs (none when they are
  not later), then correct; the last measurement time only moves forward.
- ``update(now)`` is the node's periodic step: it takes the queued measurements whose
  time has come, in time order (equal times in the order they arrived); when none was
  queued for ``sensor_timeout`` it predicts to ``now`` so the estimate keeps moving.
- ``set_pose(measurement, now)`` puts the estimate where the measurement says.
- ``differentiate(now)`` is the angular acceleration the IMU's lever arm needs, the
  change of the rates between two periodic steps, as the peer computes it.
- With ``control`` settings (``use_control``), ``command`` takes the velocity command,
  and each prediction starts with its term (control.py).
- With ``history_ns`` (``smooth_lagged_data``), a measurement older than the filter's
  time is put in its place: the filter's steps (measurements, the periodic step's
  predictions, velocity commands) are events of the package's ``CausalOrder``, so a late
  one is applied where it belongs and the later ones run again (lagged.py).
"""

from __future__ import annotations

import heapq
import itertools
from dataclasses import dataclass, field

import numpy as np

from estimation_nodes.core.causal_order import CausalOrder
from estimation_nodes.core.fusion import steps
from estimation_nodes.core.fusion.control import Control, ControlSettings
from estimation_nodes.core.fusion.lagged import (MAX_EVENTS, RANK_COMMAND, RANK_MEASUREMENT,
                                                 RANK_PREDICTION, Command, PredictTo,
                                                 Snapshot, Taken)
from estimation_nodes.core.fusion.state import STATE_SIZE, TWIST, VROLL
from estimation_nodes.core.fusion.steps import Measurement, Rejected, UnscentedWeights
from estimation_nodes.core.validation import FloatArray


#: The variance ``set_pose`` gives the entries its pose does not set (the peer's).
SET_POSE_VARIANCE = 1e-6


@dataclass(frozen=True)
class FusionSettings:
    """What the filter needs of the configuration (robot_localization's meanings).

    The state's size is ``initial_state``'s: 15, and 3 per estimated gyro bias;
    ``process_noise``, ``initial_covariance`` and ``weights.size`` match it.
    """

    #: "ekf" or "ukf".
    kind: str = "ekf"
    process_noise: FloatArray = field(default_factory=lambda: np.eye(STATE_SIZE) * 0.01)
    initial_covariance: FloatArray = field(default_factory=lambda: np.eye(STATE_SIZE) * 1e-9)
    initial_state: FloatArray = field(default_factory=lambda: np.zeros(STATE_SIZE))
    sensor_timeout_ns: int = 33_333_333
    predict_to_current_time: bool = False
    dynamic_process_noise: bool = False
    weights: UnscentedWeights = UnscentedWeights()
    #: The control term's settings (``use_control``), None without it.
    control: ControlSettings | None = None
    #: How far back a late measurement is put in its place (``smooth_lagged_data`` with
    #: ``history_length``, ns); None: a late one is corrected at the filter's time.
    history_ns: int | None = None


@dataclass
class Counts:
    """What happened to the measurements, by source (for diagnostics)."""

    applied: dict[str, int] = field(default_factory=dict)
    rejected: dict[str, int] = field(default_factory=dict)
    #: Late measurements put in their place (``smooth_lagged_data``).
    smoothed: dict[str, int] = field(default_factory=dict)
    #: Late measurements older than the history holds: corrected at the filter's time.
    beyond_history: dict[str, int] = field(default_factory=dict)
    #: Late measurements older than the last set_pose or pause: taken at its time.
    before_floor: dict[str, int] = field(default_factory=dict)

    def outcome(self, source: str, accepted: bool, before: bool | None) -> None:
        """A measurement applied or rejected; ``before`` is what it was counted as the
        last time it ran (None: the first), so a replay moves its count, not adds one."""
        if before is accepted:
            return
        if before is not None:
            table = self.applied if before else self.rejected
            table[source] -= 1
        self.add(self.applied if accepted else self.rejected, source)

    def add(self, table: dict[str, int], source: str) -> None:
        table[source] = table.get(source, 0) + 1


class FusionFilter:
    """robot_localization's filter loop over ``steps``' EKF or UKF."""

    def __init__(self, settings: FusionSettings) -> None:
        if settings.kind not in ("ekf", "ukf"):
            raise ValueError(f"filter kind must be 'ekf' or 'ukf', got {settings.kind!r}")
        self.settings = settings
        size = self.size
        if np.shape(settings.process_noise) != (size, size) or \
                np.shape(settings.initial_covariance) != (size, size) or \
                settings.weights.size != size:
            raise ValueError(f"the process noise, the initial covariance and the unscented "
                             f"weights must all be for {size} entries, as the initial state")
        self.counts = Counts()
        self._arrivals = itertools.count()
        self.reset()

    @property
    def size(self) -> int:
        """The state's entries: 15, and 3 per estimated gyro bias."""
        return int(np.size(self.settings.initial_state))

    def reset(self) -> None:
        """Back to the initial state, uninitialized, with nothing queued."""
        self.x = np.array(self.settings.initial_state, dtype=float)
        self.p = np.array(self.settings.initial_covariance, dtype=float)
        self.initialized = False
        self.last_time_ns = 0
        self._queue: list[tuple[int, int, Measurement]] = []
        # The UKF's sigma points for its next correction: the propagated ones right after
        # a prediction, None for "draw new ones" (the peer starts with all-zero points).
        size = self.size
        self._points: FloatArray | None = np.zeros((2 * size + 1, size))
        self._last_rates = np.zeros(3)
        self._last_diff_ns: int | None = None
        self.angular_acceleration = np.zeros(3)
        #: The velocity command and its term (None without ``use_control``); a reset
        #: forgets the command, as the peer's does.
        self.control = Control(self.settings.control) if self.settings.control else None
        history_ns = self.settings.history_ns
        # The time nothing is put back before: the last set_pose or pause (smoothing).
        self._history_floor_ns = -1 << 62
        self._history = None if history_ns is None else CausalOrder(self, history_ns,
                                                                    MAX_EVENTS)

    # --- the peer's FilterBase::processMeasurement --------------------------------------

    def process(self, measurement: Measurement) -> bool:
        """Predict to the measurement's time and correct; False when it was rejected."""
        accepted = self._process(measurement)[0]
        self.counts.outcome(measurement.source, accepted, None)
        return accepted

    def _process(self, measurement: Measurement) -> tuple[bool, bool]:
        """(taken, whether the state changed: a rejected one may still have predicted)."""
        if not self.initialized:
            self._initialize(measurement)
            return True, True
        delta_ns = measurement.stamp_ns - self.last_time_ns
        if delta_ns > 0:
            self.predict(delta_ns)
        try:
            self._correct(measurement)
        except Rejected:
            accepted = False
        else:
            accepted = True
        if delta_ns >= 0:
            self.last_time_ns = measurement.stamp_ns
        return accepted, accepted or delta_ns > 0

    def _initialize(self, measurement: Measurement) -> None:
        idx = list(measurement.indices)
        # New arrays: a saved state (smooth_lagged_data) holds the old ones. R with its
        # variances floored, as a correction would take it: the peer copies the
        # message's, so a negative variance there would make P indefinite.
        self.x, self.p = self.x.copy(), self.p.copy()
        self.x[idx], self.p[np.ix_(idx, idx)] = steps.subset(measurement)
        # A gyro's reading is the rate plus its bias: the rate is the reading less the
        # bias's estimate, as uncertain as both, and tied to the bias.
        for measured, bias in measurement.biased:
            self.x[measured] -= self.x[bias]
            self.p[measured, measured] += self.p[bias, bias]
            self.p[measured, bias] = self.p[bias, measured] = -self.p[bias, bias]
        self.initialized = True
        self.last_time_ns = measurement.stamp_ns

    def set_pose(self, measurement: Measurement, now_ns: int) -> None:
        """The peer's ``set_pose``: the state is the measurement's values (0 where it has
        none), the covariance its covariance there (variances floored) and 1e-6 elsewhere;
        what was queued is dropped; the last measurement time is ``now_ns``. Whether the
        filter was initialized stays as it was, as in the peer."""
        # Gyro biases are the sensors', not the pose's: kept, with their variances.
        x = np.zeros(self.size)
        x[STATE_SIZE:] = self.x[STATE_SIZE:]
        p = np.eye(self.size) * SET_POSE_VARIANCE
        p[STATE_SIZE:, STATE_SIZE:] = self.p[STATE_SIZE:, STATE_SIZE:]
        self.x, self.p = x, p
        idx = list(measurement.indices)
        self.x[idx], self.p[np.ix_(idx, idx)] = steps.subset(measurement)
        self._points = None   # the UKF's next correction draws them around the pose
        self._queue.clear()
        self._forget_history(now_ns)   # nothing goes back before the pose it was put at
        self.last_time_ns = now_ns
        self.counts.add(self.counts.applied, measurement.source)

    def _process_noise(self) -> FloatArray:
        q = self.settings.process_noise
        if not self.settings.dynamic_process_noise:
            return q
        speed = float(np.linalg.norm(self.x[TWIST]))
        dynamic = q.copy()
        dynamic[:6, :6] = speed * speed * q[:6, :6]
        return dynamic

    def predict(self, delta_ns: int) -> None:
        """Move the estimate ``delta_ns`` forward with the motion model (from the last
        measurement time)."""
        dt = delta_ns * 1e-9
        q = self._process_noise()
        if self.control is not None:
            self.x = self.control.applied(self.x, dt, self.last_time_ns + delta_ns)
        if self.settings.kind == "ekf":
            self.x, self.p = steps.ekf_predict(self.x, self.p, q, dt)
        else:
            self.x, self.p, self._points = steps.ukf_predict(
                self.x, self.p, q, dt, self.settings.weights)

    def _correct(self, measurement: Measurement) -> None:
        if self.settings.kind == "ekf":
            self.x, self.p = steps.ekf_correct(self.x, self.p, measurement)
            return
        self.x, self.p = steps.ukf_correct(
            self.x, self.p, measurement, self.settings.weights, self._points)
        self._points = None

    # --- the peer's RosFilter::integrateMeasurements -----------------------------------

    def enqueue(self, measurement: Measurement) -> None:
        heapq.heappush(self._queue, (measurement.stamp_ns, next(self._arrivals), measurement))

    @property
    def queued(self) -> int:
        return len(self._queue)

    def update(self, now_ns: int) -> int:
        """The periodic step at ``now_ns``: the measurements due, else a timeout prediction.

        Returns how many measurements it took.
        """
        taken = 0
        predict_to_now = self.settings.predict_to_current_time
        if self._queue:
            while self._queue and self._queue[0][0] <= now_ns:
                _, _, measurement = heapq.heappop(self._queue)
                self._take(measurement)
                taken += 1
        elif self.initialized and now_ns - self.last_time_ns >= self.settings.sensor_timeout_ns:
            predict_to_now = True
        if self.initialized and predict_to_now and now_ns > self.last_time_ns:
            if self._history is None:
                self._predict_to(now_ns)
            else:
                self._history.submit(now_ns, RANK_PREDICTION, PredictTo(now_ns))
        return taken

    def _take(self, measurement: Measurement) -> None:
        if self._history is None:
            self.process(measurement)
            return
        stamp_ns = measurement.stamp_ns
        # Late as the peer counts it: older than the filter's time.
        late = self.initialized and stamp_ns < self.last_time_ns
        # Nothing goes back before a set pose (or a pause): an older one is taken then.
        before_floor = stamp_ns < self._history_floor_ns
        submission = self._history.submit(max(stamp_ns, self._history_floor_ns),
                                          RANK_MEASUREMENT, Taken(measurement))
        if before_floor:
            self.counts.add(self.counts.before_floor, measurement.source)
        elif submission.too_late:
            self.counts.add(self.counts.beyond_history, measurement.source)
        elif late:
            self.counts.add(self.counts.smoothed, measurement.source)

    def _predict_to(self, now_ns: int) -> None:
        self.predict(now_ns - self.last_time_ns)
        self.last_time_ns = now_ns

    def command(self, command: FloatArray, stamp_ns: int) -> None:
        """The robot's velocity command at ``stamp_ns`` (``use_control``)."""
        if self.control is None:
            raise ValueError("a velocity command needs the control term (use_control)")
        if self._history is None:
            self.control.set(command, stamp_ns)
        else:
            self._history.submit(stamp_ns, RANK_COMMAND, Command(np.array(command, dtype=float),
                                                                 stamp_ns))

    # --- smooth_lagged_data: the filter as CausalOrder's target (lagged.py) -------------

    def snapshot(self) -> Snapshot:
        control = self.control
        return Snapshot(self.x, self.p, self._points, self.initialized, self.last_time_ns,
                        None if control is None else (control.command, control.command_ns))

    def restore(self, state: Snapshot) -> None:
        self.x, self.p, self._points = state.x, state.p, state.points
        self.initialized, self.last_time_ns = state.initialized, state.last_time_ns
        if state.command is not None and self.control is not None:
            self.control.command, self.control.command_ns = state.command

    def apply(self, event, first_time: bool) -> bool:
        """One event in its place; False when it left the state as it was."""
        if isinstance(event, Taken):
            accepted, changed = self._process(event.measurement)
            # Counted once: a replay that takes what was rejected (or the reverse) moves
            # its count.
            self.counts.outcome(event.measurement.source, accepted, event.accepted)
            event.accepted = accepted
            return changed
        if isinstance(event, PredictTo):
            if not self.initialized or event.stamp_ns <= self.last_time_ns:
                return False
            self._predict_to(event.stamp_ns)
            return True
        assert self.control is not None
        self.control.set(event.command, event.stamp_ns)
        return True

    def pause(self, now_ns: int) -> list[Measurement]:
        """The periodic step with processing toggled off (the peer's ``toggle``): what was
        queued is dropped (returned, to count) and the filter's time is ``now_ns``, so
        that the first prediction after does not span the pause."""
        dropped = [measurement for _, _, measurement in self._queue]
        self._queue.clear()
        if self.initialized:
            self.last_time_ns = now_ns
            self._forget_history(now_ns)   # the state before the pause is not rebuilt
        return dropped

    def _forget_history(self, now_ns: int) -> None:
        """Nothing is put back before ``now_ns`` (a set pose, a pause): the history of
        ``smooth_lagged_data`` starts again there."""
        if self._history is not None:
            self._history.clear()
        self._history_floor_ns = now_ns

    def differentiate(self, now_ns: int) -> None:
        """The angular acceleration since the last periodic step (the peer's estimate)."""
        if not self.initialized:
            return
        rates = self.x[VROLL:VROLL + 3].copy()
        if self._last_diff_ns is not None and now_ns > self._last_diff_ns:
            self.angular_acceleration = (rates - self._last_rates) / (
                (now_ns - self._last_diff_ns) * 1e-9)
        self._last_rates = rates
        self._last_diff_ns = now_ns
