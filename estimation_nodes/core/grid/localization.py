"""The running grid localization: belief, odometry reference, and the update rule.

With ``kidnap_probability`` > 0 a uniform share of that much probability is
mixed into the belief before each correction (the chance that the robot was
carried anywhere since the last update), so a kidnapped robot is found again
by the scans alone; 0 keeps the exact filter (recovery through
``global_localization``).

As AMCL: odometry is followed continuously, and a scan updates the filter
(a prediction with the motion since the last update, then the correction)
only once the robot moved ``update_min_d`` or turned ``update_min_a`` since
then; the first scan corrects at once. An odometry step longer than
``max_odom_jump`` is a jump (a reset odometry, a teleport): it is not taken
as motion, and odometry is followed from the new pose. A step that fails
(a scan every state rules out) leaves everything as it was.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from collections import deque
from dataclasses import dataclass

import numpy as np

from estimation_nodes.core.grid import steps as grid
from estimation_nodes.core.validation import FloatArray

Pose = tuple[float, float, float]
#: Odometry poses kept to find the one of a scan's time (at 50 Hz, 4 s).
ODOMETRY_HISTORY = 200


@dataclass(frozen=True)
class Estimate:
    """What the localizer publishes: the most likely pose, the belief's covariance
    around it, and the probability near it."""

    pose: Pose
    covariance: FloatArray
    quality: float


class GridLocalization:
    """Grid Markov localization of one robot on one map."""

    def __init__(self, model: grid.GridModel, noise: grid.OdometryNoise, update_min_d: float,
                 update_min_a: float, max_odom_jump: float,
                 kidnap_probability: float = 0.0) -> None:
        self.model = model
        self.noise = noise
        # Load a large grid's compiled kernels now, not during the first scan.
        grid.compiled_kernels(int(np.prod(model.shape)))
        self._min_d, self._min_a, self._max_jump = update_min_d, update_min_a, max_odom_jump
        self._kidnap = kidnap_probability
        self._uniform = grid.uniform_over_free(model) if kidnap_probability > 0 else None
        self.belief: FloatArray = grid.uniform_over_free(model)
        self.log_evidence = float("nan")
        #: The odometry pose at the last update (None: no update yet) and the latest one.
        self._reference: Pose | None = None
        self._latest: Pose | None = None
        #: (stamp ns, pose) of recent odometry, oldest first, for the pose at a scan's time.
        self._history: deque[tuple[int, Pose]] = deque(maxlen=ODOMETRY_HISTORY)
        self.updates = 0

    def global_localization(self) -> None:
        """Not knowing where the robot is: uniform over the free cells."""
        self.belief = grid.uniform_over_free(self.model)
        self.log_evidence = float("nan")

    def set_prior(self, pose: Pose, covariance: FloatArray) -> None:
        """A Gaussian prior (RViz's "2D Pose Estimate")."""
        self.belief = grid.gaussian_prior(self.model, *pose, covariance)

    def on_odometry(self, pose: Pose, stamp_ns: int | None = None) -> bool:
        """Follow odometry; False when the step was a jump (not taken as motion)."""
        latest = self._latest
        if latest is not None and math.hypot(pose[0] - latest[0],
                                             pose[1] - latest[1]) > self._max_jump:
            # What was moved before the jump is lost with it; follow on from here.
            self._history.clear()
            self._latest = pose
            if self._reference is not None:
                self._reference = pose
            self._remember(pose, stamp_ns)
            return False
        self._latest = pose
        self._remember(pose, stamp_ns)
        return True

    def _remember(self, pose: Pose, stamp_ns: int | None) -> None:
        if stamp_ns is not None and (not self._history or stamp_ns >= self._history[-1][0]):
            self._history.append((stamp_ns, pose))

    def odometry_covers(self, stamp_ns: int) -> bool:
        """Whether odometry up to ``stamp_ns`` (a scan's time) has come in."""
        return bool(self._history) and self._history[-1][0] >= stamp_ns

    def _odometry_at(self, stamp_ns: int | None) -> Pose | None:
        """The latest odometry pose at or before ``stamp_ns`` (the latest one, without)."""
        if stamp_ns is None or not self._history:
            return self._latest
        index = bisect_right([stamp for stamp, _ in self._history], stamp_ns)
        return self._history[index - 1][1] if index else None

    def due(self, stamp_ns: int | None = None) -> bool:
        """Whether a scan taken at ``stamp_ns`` updates the filter: the first once odometry
        is there, later ones after enough motion since the last update."""
        pose = self._odometry_at(stamp_ns)
        if pose is None:
            return False
        if self._reference is None:
            return True
        dx = pose[0] - self._reference[0]
        dy = pose[1] - self._reference[1]
        turned = abs(math.remainder(pose[2] - self._reference[2], 2 * math.pi))
        return math.hypot(dx, dy) >= self._min_d or turned >= self._min_a

    def update(self, ranges: FloatArray, angles: FloatArray,
               stamp_ns: int | None = None) -> None:
        """Predict with the odometry from the last update to the scan's time, correct with
        the scan."""
        pose = self._odometry_at(stamp_ns)
        if pose is None:
            raise ValueError("no odometry yet: the motion since the last update is unknown")
        belief = self.belief
        if self._reference is not None:
            delta = grid.odometry_delta(self._reference, pose)
            belief = grid.predict(belief, self.model, delta, self.noise)
        if self._uniform is not None:
            # The robot may have been carried anywhere: a little of the belief everywhere,
            # so a kidnapped robot is found again by the scans alone.
            belief = (1.0 - self._kidnap) * belief + self._kidnap * self._uniform
        self.belief, self.log_evidence = grid.correct_scan(belief, self.model, ranges, angles)
        self._reference = pose
        self.updates += 1

    def estimate(self, radius: float, angle: float) -> Estimate:
        state = grid.most_likely_state(self.belief)
        pose = grid.pose_of(self.model, state)
        return Estimate(pose, grid.covariance_around(self.belief, self.model, pose),
                        grid.mass_near(self.belief, self.model, pose, radius, angle))

    def belief_map(self) -> np.ndarray:
        return grid.belief_map(self.belief)

    def entropy_bits(self) -> float:
        return grid.entropy_bits(self.belief)
