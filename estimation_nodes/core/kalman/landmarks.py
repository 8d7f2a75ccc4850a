"""Localization among known landmarks: the running EKF or UKF estimate and its event rules.

Odometry is a twist (v, w) that drives the unicycle from its time until the next
event; a camera frame is a set of range-bearing observations of landmarks by id,
all taken at the frame's time. The filter predicts to each event's time with the
twist in force, then applies the frame's observations one after the other.

An observation of an id that is not on the map is counted and ignored. One whose
normalized innovation squared exceeds the gate (the ``gate_probability``
quantile of chi-square with 2 degrees of freedom) is counted and skipped: a
wrong data association or a reflection must not pull the estimate. But a filter
whose estimate went wrong rejects every true observation too, and would stay
lost. So when no observation was accepted for ``recovery_time`` seconds while
some were gated, the filter admits it no longer knows where it is: its
covariance grows by ``recovery_std`` (in position and heading), and the gate
judges the observation again from that; if it still does not fit, the
covariance grows again after another ``recovery_time``, until observations pass.
The gate stays on throughout, so a wrong identification (a landmark seen behind
the robot) is rejected even while the filter recovers. A frame of two landmarks or
more is quicker than the widening: it places a lost filter by itself
(relocalization.py), and so does a frame that comes recovery_time after the last
used observation and fits nowhere.

Odometry that reports commanded speeds, not measured ones, meets two facts of the
robot it drives: the robot follows a command ``odometry_delay`` seconds after it is
stamped, and at ``odometry_scale`` (forward, turn) times the commanded speeds. Both
default to the identity (delay 0, scale 1) of measured odometry.

A camera's range scale is rarely known to better than a few percent, and an error
in it is the same at every frame: a bias the filter, taking frames as independent,
averages into a confident wrong pose. With ``range_scale_std`` > 0 the scale is
estimated with the pose, a fourth state whose prior is ``range_scale`` with that
std: landmarks at different ranges and bearings disagree on a wrong scale, so the
observations tell it from the pose. ``pose`` and ``pose_covariance`` are the pose's
part of the state either way.
"""

from __future__ import annotations

import math
from collections import Counter, deque
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np

from estimation_nodes.core.kalman import ekf, range_bearing, relocalization, ukf
from estimation_nodes.core.kalman.ekf import Innovation
from estimation_nodes.core.kalman.range_bearing import EUCLIDEAN, Ranging, SensorPose
from estimation_nodes.core.kalman.unicycle import UnicycleNoise
from estimation_nodes.core.validation import FloatArray, as_finite_array, check_covariance

FILTERS = ("ekf", "ukf")


def chi_square_2_quantile(probability: float) -> float:
    """The chi-square (2 degrees of freedom) quantile: exactly -2 ln(1 - p)."""
    if probability >= 1.0:
        return math.inf
    return -2.0 * math.log1p(-probability)


@dataclass(frozen=True)
class LandmarkModel:
    """Everything the landmark filter needs besides its state, validated on construction."""

    kind: str
    noise: UnicycleNoise
    #: The range's std is range_std + range_std_per_m * range: a camera that measures
    #: range by a landmark's apparent size errs in proportion to the range.
    range_std: float
    range_std_per_m: float
    bearing_std: float
    sensor: SensorPose
    #: Landmark id -> (x, y) in the map frame.
    landmarks: Mapping[int, tuple[float, float]]
    gate_probability: float
    recovery_time: float
    #: The std of x, y (m) and heading (rad) a recovery adds to the covariance.
    recovery_std: tuple[float, float]
    #: The UKF's sigma points; None for the EKF.
    points: ukf.SigmaPoints | None = None
    #: What the sensor's range measures (the distance, or the depth along its axis).
    ranging: Ranging = EUCLIDEAN
    #: The EKF's passes per observation (1: the EKF; more: the iterated EKF).
    iterations: int = 1
    #: Seconds between an odometry message's stamp and the robot driving it.
    odometry_delay: float = 0.0
    #: (forward, turn): the speeds the robot drives per unit of reported speed.
    odometry_scale: tuple[float, float] = (1.0, 1.0)
    #: The std of the prior on the range's scale (mean ranging.scale); 0: the scale is
    #: ranging.scale, not estimated.
    range_scale_std: float = 0.0
    #: The std of sensor_pose (x m, y m, yaw rad): how well the mount is known. The
    #: filter takes the mount as exact; the published pose covariance adds what its error
    #: makes (Schmidt's consider covariance, to first order: range_bearing.mount_covariance).
    sensor_pose_std: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def state_size(self) -> int:
        """3 (x, y, heading), or 4 with the range's scale estimated."""
        return 4 if self.range_scale_std > 0 else 3

    def __post_init__(self) -> None:
        if self.kind not in FILTERS:
            raise ValueError(f"filter: expected one of {FILTERS}, got {self.kind!r}")
        if self.kind == "ukf" and self.points is None:
            raise ValueError("points: the UKF needs its sigma points")
        for name in ("range_std", "bearing_std"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name}: expected a finite number > 0, got {value!r}")
        if not (math.isfinite(self.range_std_per_m) and self.range_std_per_m >= 0):
            raise ValueError(f"range_std_per_m: expected a finite number >= 0, got "
                             f"{self.range_std_per_m!r}")
        if not 0 < self.gate_probability <= 1:
            raise ValueError(f"gate_probability: expected 0 < p <= 1, got "
                             f"{self.gate_probability!r}")
        if not (math.isfinite(self.recovery_time) and self.recovery_time > 0):
            raise ValueError(f"recovery_time: expected a finite number > 0, got "
                             f"{self.recovery_time!r}")
        if not all(math.isfinite(v) and v > 0 for v in self.recovery_std) \
                or len(self.recovery_std) != 2:
            raise ValueError(f"recovery_std: expected [position m, heading rad] > 0, got "
                             f"{list(self.recovery_std)}")
        if not (isinstance(self.iterations, int) and 1 <= self.iterations <= 100):
            raise ValueError(f"ekf.iterations: expected an integer in 1..100, got "
                             f"{self.iterations!r}")
        if not (math.isfinite(self.odometry_delay) and 0 <= self.odometry_delay <= 10):
            raise ValueError(f"odometry_delay: expected 0 <= seconds <= 10, got "
                             f"{self.odometry_delay!r}")
        if len(self.odometry_scale) != 2 or not all(
                math.isfinite(v) and 0 < v <= 10 for v in self.odometry_scale):
            raise ValueError(f"odometry_scale: expected [forward, turn] in (0, 10], got "
                             f"{list(self.odometry_scale)}")
        # A prior wider than a quarter would put sigma points and iterates near a scale
        # of 0 (no range at all): no camera is that badly known.
        if not (math.isfinite(self.range_scale_std) and 0 <= self.range_scale_std <= 0.25):
            raise ValueError(f"range_scale_std: expected 0 <= std <= 0.25, got "
                             f"{self.range_scale_std!r}")
        if len(self.sensor_pose_std) != 3 or not all(
                math.isfinite(v) and 0 <= v <= 1 for v in self.sensor_pose_std):
            raise ValueError(f"sensor_pose_std: expected [x, y, yaw] in [0, 1], got "
                             f"{list(self.sensor_pose_std)}")
        if self.points is not None and self.points.n != self.state_size:
            raise ValueError(f"points: sigma points for a state of {self.points.n}, but the "
                             f"state has {self.state_size}")
        for key, (lx, ly) in self.landmarks.items():
            if not (math.isfinite(lx) and math.isfinite(ly)):
                raise ValueError(f"landmarks: landmark {key} at ({lx}, {ly}) is not finite")

    def R(self, measured_range: float) -> FloatArray:
        """The measurement noise of an observation at ``measured_range``."""
        range_std = self.range_std + self.range_std_per_m * measured_range
        return np.diag([range_std ** 2, self.bearing_std ** 2])

    @property
    def gate(self) -> float:
        return chi_square_2_quantile(self.gate_probability)


@dataclass(frozen=True)
class Observation:
    """One landmark seen in a frame: its id, range (m) and bearing (rad)."""

    landmark: int
    range: float
    bearing: float


@dataclass
class Outcome:
    """What became of one observation: 'used', 'gated', 'unknown', 'invalid' (not finite,
    or no bearing), or 'unstable' (its correction failed or would have left no valid
    covariance); its NIS where it was computed."""

    observation: Observation
    verdict: str
    nis: float = math.nan


class LandmarkLocalization:
    """The pose (x, y, heading) and its covariance, advanced by odometry and landmarks."""

    def __init__(self, model: LandmarkModel, x0: object, P0: object,
                 t0: float | None = None) -> None:
        """Start at pose ``x0`` with covariance ``P0``, at time ``t0``; with ``t0`` None the
        filter starts at its first event's time, whatever event that is."""
        self.model = model
        pose = as_finite_array("initial_pose", x0, ndim=1)
        if pose.size != 3:
            raise ValueError(f"initial_pose: expected [x, y, yaw], got {pose.tolist()}")
        pose_P = check_covariance("initial_covariance", P0, 3)
        self.x, self.P = pose, pose_P
        if model.state_size == 4:
            self.x = np.append(pose, model.ranging.scale)
            self.P = np.zeros((4, 4))
            self.P[:3, :3], self.P[3, 3] = pose_P, model.range_scale_std ** 2
        self.t = None if t0 is None else float(t0)
        self.twist = (0.0, 0.0)
        #: Twists stamped but not yet driven (odometry_delay): (time driven from, twist).
        self._coming: deque[tuple[float, tuple[float, float]]] = deque()
        self.counts: Counter[str] = Counter()
        self._last_used = self.t
        self._gated_since_used = 0

    @property
    def model(self) -> LandmarkModel:
        return self._model

    @model.setter
    def model(self, model: LandmarkModel) -> None:
        """A new model (a node's parameters changed) is taken whole, its gate included;
        the state's size is the first model's (range_scale_std is fixed at the start)."""
        previous: LandmarkModel | None = getattr(self, "_model", None)
        if previous is not None and model.state_size != previous.state_size:
            raise ValueError("range_scale_std: whether the scale is estimated is fixed at "
                             "the start")
        self._model = model
        self._gate = model.gate

    @property
    def pose(self) -> FloatArray:
        """(x, y, heading): the pose's part of the state."""
        return self.x[:3]

    @property
    def pose_covariance(self) -> FloatArray:
        """The pose's 3 x 3 block of the covariance, with what the mount's uncertainty
        adds (sensor_pose_std; nothing where the mount is exact)."""
        if not any(self.model.sensor_pose_std):
            return self.P[:3, :3]
        return self.P[:3, :3] + range_bearing.mount_covariance(
            self.x, self.model.sensor, self.model.sensor_pose_std)

    @property
    def range_scale(self) -> tuple[float, float]:
        """The range's scale (range_bearing.range_scale) and its std (0 where it is not
        estimated)."""
        std = math.sqrt(max(float(self.P[3, 3]), 0.0)) if len(self.x) > 3 else 0.0
        return range_bearing.range_scale(self.x, self.model.ranging), std

    # --- state, as causal_order.py saves and restores it ---------------------------------

    def snapshot(self) -> tuple:
        return (self.x, self.P, self.t, self.twist, tuple(self._coming), self.counts.copy(),
                self._last_used, self._gated_since_used)

    def restore(self, state: tuple) -> None:
        (self.x, self.P, self.t, self.twist, coming, counts, self._last_used,
         self._gated_since_used) = state
        self._coming = deque(coming)
        self.counts = counts.copy()

    # --- events --------------------------------------------------------------------------

    def on_odometry(self, t: float, v: float, w: float) -> None:
        """The twist in force from ``t`` (plus odometry_delay) on; the pose predicted to
        ``t`` with the twists before it."""
        if not (math.isfinite(v) and math.isfinite(w)):
            raise ValueError(f"odometry: expected finite speeds, got v={v!r}, w={w!r}")
        now = self._predict_to(t)
        forward, turn = self.model.odometry_scale
        twist = (float(v) * forward, float(w) * turn)
        if self.model.odometry_delay == 0:
            self.twist = twist
        else:
            self._coming.append((now + self.model.odometry_delay, twist))

    def on_frame(self, t: float, observations: Iterable[Observation]) -> list[Outcome]:
        """A camera frame at ``t``: predict to it, then apply each observation (a lost
        filter is placed by the frame alone first, where it can be: the observations that
        placed it are used for that)."""
        self._predict_to(t)
        observations = list(observations)
        placed: list[Outcome] = []
        if self._lost() or (self._overdue() and not any(map(self._fits, observations))):
            placed = self._relocalize(observations)
        placing = {id(outcome.observation): outcome for outcome in placed}
        return [placing.get(id(seen)) or self._observe(seen) for seen in observations]

    def _overdue(self) -> bool:
        """Whether recovery_time passed since an observation was last used (a frame after
        a long time unseen that fits nowhere is as lost as gated frames for that long)."""
        return self.t is not None and self._last_used is not None \
            and self.t - self._last_used >= self.model.recovery_time

    def _fits(self, observation: Observation) -> bool:
        """Whether ``observation`` is of a known landmark and passes the gate."""
        landmark = self.model.landmarks.get(observation.landmark)
        z = np.array([observation.range, observation.bearing], dtype=np.float64)
        if landmark is None or not (np.isfinite(z).all() and z[0] > 0):
            return False
        try:
            return bool(self._innovation(z, landmark).nis <= self._gate)
        except (ValueError, np.linalg.LinAlgError):
            return False

    def _relocalize(self, observations: list[Observation]) -> list[Outcome]:
        """The pose and covariance one frame gives (relocalization.py), from its usable
        observations of landmarks it sees once; the range's scale and its variance stay.
        The outcomes of the observations that placed it (none where it was not placed)."""
        model = self.model
        ids = Counter(seen.landmark for seen in observations)
        placing = [(seen, np.array([seen.range, seen.bearing], dtype=np.float64))
                   for seen in observations
                   if seen.landmark in model.landmarks and ids[seen.landmark] == 1]
        placing = [(seen, z) for seen, z in placing if relocalization.usable(z, model.ranging)]
        placed = relocalization.place(
            [(model.landmarks[seen.landmark], z) for seen, z in placing], model.sensor,
            model.ranging, self.x[3:], self.P[3:, 3:], model.R, model.gate_probability)
        if placed is None:
            return []
        pose, covariance = placed
        P = self.P.copy()
        P[:3, :], P[:, :3] = 0.0, 0.0
        P[:3, :3] = covariance
        self.x, self.P = np.append(pose, self.x[3:]), P
        self.counts["relocalized"] += 1
        self.counts["used"] += len(placing)
        self._last_used, self._gated_since_used = self.t, 0
        return [Outcome(seen, "used") for seen, _ in placing]

    def _predict_to(self, t: float) -> float:
        """The estimate predicted to ``t``; the filter's time after it (``t``, or a later
        one for a late event)."""
        if not math.isfinite(t):
            raise ValueError(f"t: expected a finite time, got {t!r}")
        if self.t is None:
            self.t = self._last_used = t
            return t
        if t < self.t:
            # A late event is applied at the filter's time (causal_order.py puts them
            # in order first; what it cannot is counted).
            self.counts["late"] += 1
            return self.t
        while self._coming and self._coming[0][0] <= t:
            start, twist = self._coming.popleft()
            self._drive_to(self.t, start)
            self.twist = twist
        self._drive_to(self.t, t)
        return t

    def _drive_to(self, now: float, t: float) -> None:
        """The pose predicted from the filter's time ``now`` to ``t`` with the twist in
        force."""
        dt = t - now
        if dt <= 0:
            return
        v, w = self.twist
        model = self.model
        if model.kind == "ekf":
            self.x, self.P = ekf.predict(self.x, self.P, v, w, dt, model.noise)
        else:
            assert model.points is not None
            self.x, self.P = ukf.predict(self.x, self.P, v, w, dt, model.noise, model.points)
        self.t = t

    def _innovation(self, z: FloatArray, landmark: tuple[float, float]) -> Innovation:
        model = self.model
        R = model.R(float(z[0]))
        if model.kind == "ekf":
            return ekf.innovation(self.x, self.P, z, landmark, model.sensor, R, model.ranging)
        assert model.points is not None
        return ukf.innovation(self.x, self.P, z, landmark, model.sensor, R, model.points,
                              model.ranging)

    def _observe(self, observation: Observation) -> Outcome:
        landmark = self.model.landmarks.get(observation.landmark)
        if landmark is None:
            self.counts["unknown"] += 1
            return Outcome(observation, "unknown")
        z = np.array([observation.range, observation.bearing], dtype=np.float64)
        if not (np.isfinite(z).all() and z[0] > 0):
            self.counts["invalid"] += 1
            return Outcome(observation, "invalid")
        try:
            observed = self._innovation(z, landmark)
            nis = observed.nis
        except (ValueError, np.linalg.LinAlgError):
            self.counts["invalid"] += 1
            return Outcome(observation, "invalid")
        if nis > self._gate:
            if not self._lost():
                self.counts["gated"] += 1
                self._gated_since_used += 1
                return Outcome(observation, "gated", nis)
            # Lost: the covariance widens, and the gate judges again from it.
            self._widen()
            observed = self._innovation(z, landmark)
            nis = observed.nis
            if nis > self._gate:
                self.counts["gated"] += 1
                self._gated_since_used += 1
                return Outcome(observation, "gated", nis)
            self.counts["recovered"] += 1
        if not self._apply(observed, z, landmark):
            self.counts["unstable"] += 1
            return Outcome(observation, "unstable", nis)
        self.counts["used"] += 1
        self._last_used, self._gated_since_used = self.t, 0
        return Outcome(observation, "used", nis)

    @property
    def lost(self) -> bool:
        """Whether every observation was gated for recovery_time seconds (the next one
        widens the covariance)."""
        return self._lost()

    def _lost(self) -> bool:
        if self.t is None or self._last_used is None:
            return False
        return bool(self._gated_since_used) \
            and self.t - self._last_used >= self.model.recovery_time

    def _widen(self) -> None:
        """The covariance grown by recovery_std in position and heading: at each recovery
        the gate opens further, until the observations fit again."""
        position, heading = self.model.recovery_std
        widening = np.zeros(len(self.x))
        widening[:3] = position ** 2, position ** 2, heading ** 2
        self.P = self.P + np.diag(widening)
        self.counts["recoveries"] += 1
        # Each widening gets its recovery_time for the observations to pass.
        self._last_used = self.t

    def _apply(self, observed: Innovation, z: FloatArray,
               landmark: tuple[float, float]) -> bool:
        """The correction applied where it leaves a finite estimate with a positive definite
        covariance (the UKF's P - K S K' need not, after a large innovation)."""
        model = self.model
        try:
            if model.kind == "ekf" and model.iterations > 1:
                x, P, converged = ekf.correct_iterated(
                    self.x, self.P, observed, z, landmark, model.sensor, model.R(float(z[0])),
                    model.ranging, model.iterations)
                if not converged:
                    # the single pass's answer (ekf.correct_iterated says when)
                    self.counts["iterations_fell_back"] += 1
            elif model.kind == "ekf":
                x, P = ekf.correct(self.x, self.P, observed, model.R(float(z[0])))
            else:
                x, P = ukf.correct(self.x, self.P, observed)
        except (ValueError, np.linalg.LinAlgError):
            # an iterate on the landmark itself (no bearing), or a singular S
            return False
        if not (np.isfinite(x).all() and np.isfinite(P).all()):
            return False
        try:
            np.linalg.cholesky(P)
        except np.linalg.LinAlgError:
            return False
        self.x, self.P = x, P
        return True
