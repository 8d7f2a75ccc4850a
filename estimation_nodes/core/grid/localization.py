"""The running grid localization: belief, odometry reference, and the update rule.

With ``kidnap_probability`` > 0 a uniform share of that much probability is
mixed into the belief before each correction (the chance that the robot was
carried anywhere since the last update), so a kidnapped robot is found again
by the scans alone; 0 keeps the exact filter (recovery through
``global_localization``).

With ``independent_beams`` K, a scan of N > K beams corrects with its likelihood raised
to K / N (``laser.scan_weight``): its beams are not N independent measurements, and
taken as such they make the belief sure of a place the next scans may rule out.

As AMCL: odometry is followed continuously, and a scan updates the filter
(a prediction with the motion since the last update, then the correction)
only once the robot moved ``update_min_d`` or turned ``update_min_a`` since
then; the first scan corrects at once. An odometry step longer than
``max_odom_jump`` is a jump (a reset odometry, a teleport): it is not taken
as motion, and odometry is followed from the new pose. A step that fails
(a scan every state rules out, an argument refused) leaves everything as it was.

With ``belief_floor`` > 0 the states of less probability are dropped after each
correction (their total is ``last_dropped``), and the steps run over the boxes of
the states left, grown by what a prediction can reach (grid/window.py): a tracked
robot's update then costs what its few square metres cost, not the building. The
kidnap share then goes on a coarse lattice of one state in eight, half of it at
each update in turn (``window.correct_boxes``, ``window.lattice_cells``), scored
with the scan. 0 keeps the dense filter.

What ``estimate`` publishes carries a doubt on the most likely place (grid/failure.py):
the kidnap share's posterior probability at each update, all of it when the most
likely state jumped beyond the prediction's reach, halved by each update that does not
renew it, plus what belief_floor dropped (``lost_probability``): the quality is that
much lower, the covariance that much the robot's anywhere on the free cells. With
belief_floor and a kidnap share it also carries the posterior of the odometry having
failed (``failure.Astray``: the robot anywhere within metres of the predicted pose or
of the last update's), scored on the kidnap lattice's states around them: the quality that much
lower, the covariance that component's second moment added.

Each method checks what it is given (a pose of three finite numbers, a scan of
readings as ``laser.check_scan`` says, a stamp that is an integer) and raises
``InvalidInputError`` naming it; the belief it holds is its own, so the steps
on it are not checked again.
"""

from __future__ import annotations

import dataclasses
import math
from bisect import bisect_right
from collections import deque
from dataclasses import dataclass
from enum import Enum

import numpy as np

from estimation_nodes.core.errors import InvalidInputError
from estimation_nodes.core.grid import failure, scan_fit, window
from estimation_nodes.core.grid.belief import (
    _covariance_around,
    _entropy_bits,
    _mass_near,
    _most_likely_state,
    _pose_of,
    _refined_pose,
)
from estimation_nodes.core.grid.correction import _correct_in
from estimation_nodes.core.grid.held import HeldBelief
from estimation_nodes.core.grid.laser import (
    _correct_scan,
    _scan_log_likelihood,
    check_scan,
    scan_weight,
)
from estimation_nodes.core.grid.model import (
    GridModel,
    _states,
    check_pose,
    compiled_kernels,
    mounting_pose,
)
from estimation_nodes.core.grid.motion import (
    OdometryNoise,
    _normalized,
    _predict,
    _spread,
    odometry_delta,
)
from estimation_nodes.core.grid.priors import (gaussian_prior, gaussian_prior_window,
                                               uniform_over_free)
from estimation_nodes.core.validation import (
    FloatArray,
    check_integer,
    check_non_negative,
    short,
)

Pose = tuple[float, float, float]
UNIFORM = "the belief was made uniform over the free cells (no initial pose)"
#: Odometry poses kept to find the one of a scan's time: 5 s at 200 Hz, more than a scan
#: waits for its odometry (odom_wait) at any rate a robot publishes it.
ODOMETRY_HISTORY = 1000


@dataclass(frozen=True)
class Estimate:
    """What the localizer publishes: the most likely pose (the belief's mean over the
    most likely state and its neighbours: finer than the grid), the belief's covariance
    around it, and the probability near it, both with the doubt on that place
    (``GridLocalization.lost_probability``)."""

    pose: Pose
    covariance: FloatArray
    quality: float


class OdometryStep(Enum):
    """How ``GridLocalization.on_odometry`` took a message."""

    #: Followed as motion.
    TAKEN = "taken"
    #: Farther than max_odom_jump from the last pose: not motion; followed from the new pose.
    JUMP = "jump"
    #: Stamped as the last one taken: ignored. The first pose at a time is that time's pose
    #: (tf2 keeps the first of repeated data too), so a scan of that time predicts with the
    #: same odometry whether it is answered live, as soon as that first one came, or
    #: replayed after all of them (real logs repeat stamps: the imported Intel log, 4,819
    #: of its 14,541 odometry messages).
    REPEATED_STAMP = "repeated stamp"


class GridLocalization:
    """Grid Markov localization of one robot on one map."""

    def __init__(self, model: GridModel, noise: OdometryNoise, update_min_d: float,
                 update_min_a: float, max_odom_jump: float,
                 kidnap_probability: float = 0.0,
                 independent_beams: int | None = None, belief_floor: float = 0.0,
                 odometry_failure_probability: float = failure.ASTRAY_PROBABILITY) -> None:
        if not isinstance(model, GridModel):
            raise InvalidInputError(f"model: expected a GridModel, got {type(model).__name__}")
        if not isinstance(noise, OdometryNoise):
            raise InvalidInputError(
                f"noise: expected an OdometryNoise, got {type(noise).__name__}")
        update_min_d = check_non_negative("update_min_d", update_min_d)
        update_min_a = check_non_negative("update_min_a", update_min_a)
        max_odom_jump = _at_least_zero("max_odom_jump", max_odom_jump)
        kidnap_probability = check_non_negative("kidnap_probability", kidnap_probability)
        if kidnap_probability > 1.0:
            raise InvalidInputError(
                f"kidnap_probability: expected a probability in [0, 1], got {kidnap_probability}")
        odometry_failure_probability = check_non_negative("odometry_failure_probability",
                                                          odometry_failure_probability)
        if odometry_failure_probability >= 1.0:
            raise InvalidInputError(f"odometry_failure_probability: expected a probability "
                                    f"below 1, got {odometry_failure_probability}")
        if independent_beams is not None:
            scan_weight(independent_beams, 1)   # raises on a count below 1
        belief_floor = check_non_negative("belief_floor", belief_floor)
        if belief_floor >= 1.0:
            raise InvalidInputError(f"belief_floor: expected a probability below 1, got "
                                    f"{belief_floor}")
        self.model = model
        self.noise = noise
        self._independent_beams = independent_beams
        # Load a large grid's compiled kernels now, not during the first scan.
        compiled_kernels(int(np.prod(model.shape)))
        self._min_d, self._min_a, self._max_jump = update_min_d, update_min_a, max_odom_jump
        self._kidnap = kidnap_probability
        self._astray_probability = odometry_failure_probability
        self._floor = belief_floor
        self._free_states = int(model.free.sum()) * model.heading_bins
        #: The belief: its windows (disjoint boxes holding every state with probability,
        #: the whole grid with belief_floor 0), the windows the steps run over. None:
        #: uniform, made when first read, so that a belief given its initial pose before
        #: then never holds the whole building (hundreds of MB).
        self._held: HeldBelief | None = None
        self.log_evidence = float("nan")
        #: The probability belief_floor dropped at the last update.
        self.last_dropped = 0.0
        #: The doubt that the most likely place holds the robot (grid/failure.py), the
        #: place it is about (the last update's most likely pose), and where the robot is
        #: if it is not there: anywhere on the free cells.
        self.doubt = 0.0
        self.doubt_cause = failure.Doubt.NONE
        self._mode: Pose | None = None
        #: The odometry-failure component's posterior, faded over the updates.
        self.astray = failure.Astray.none()
        #: What the belief was made from before any scan (``standing`` says it).
        self._started = UNIFORM
        self._anywhere = failure.spread_of(model)
        #: The odometry pose at the last update (None: no update yet) and the latest one.
        self._reference: Pose | None = None
        self._latest: Pose | None = None
        #: (stamp ns, pose) of recent odometry, oldest first, for the pose at a scan's time.
        self._history: deque[tuple[int, Pose]] = deque(maxlen=ODOMETRY_HISTORY)
        self.updates = 0
        #: The beams of the last update (ranges, angles), which the model's scan_fit
        #: refines the pose with; None before the first and after a new prior.
        self._last_scan: tuple[FloatArray, FloatArray] | None = None

    @property
    def belief(self) -> FloatArray:
        """The belief over the grid's states (heading, row, column). With belief_floor a
        new array the building's size, made from the windows held (for tests and tools:
        the localizer itself reads its windows)."""
        if self._floor > 0.0:
            return self._windows.gather(window.full_box(self.model))
        return self._windows.dense()

    @property
    def _windows(self) -> HeldBelief:
        if self._held is None:
            self._held = self._uniform()
        return self._held

    def _uniform(self) -> HeldBelief:
        """Not knowing where the robot is (``uniform_over_free``): with belief_floor held
        in the windows of the free cells, without a belief the building's size."""
        model = self.model
        if self._floor <= 0.0:
            return HeldBelief.whole(uniform_over_free(model))
        layer = model.free / float(np.count_nonzero(model.free) * model.heading_bins)
        boxes = window.support_boxes(model.free)
        # Every heading layer the same: held once, read through a view that repeats it
        # (the building's size in memory only once a scan corrects it).
        parts = [np.broadcast_to(layer[r0:r1, c0:c1].copy(),
                                 (model.heading_bins, r1 - r0, c1 - c0))
                 for r0, r1, c0, c1 in boxes]
        return HeldBelief(model.shape, boxes, parts)

    def global_localization(self) -> None:
        """Not knowing where the robot is: uniform over the free cells."""
        self._take(self._uniform(), 0.0)
        self.log_evidence = float("nan")
        self._forget_doubt()
        self._started = UNIFORM

    def set_prior(self, pose: Pose, covariance: FloatArray) -> None:
        """A Gaussian prior (RViz's "2D Pose Estimate")."""
        x, y, yaw = check_pose("pose", pose)
        # Made in full before it is taken: the prior refused, the belief is as it was.
        if self._floor > 0.0:
            # Within the prior's box only: nothing the building's size.
            box, part, left_out = gaussian_prior_window(self.model, x, y, yaw, covariance,
                                                        self._floor)
            part, dropped = window.drop_below(part, self._floor)
            self._take(HeldBelief.within(self.model.shape, box, part), dropped + left_out)
        else:
            # Written over the dense belief held (a building's is hundreds of MB), if any.
            held = None if self._held is None else self._held.dense()
            self._hold(gaussian_prior(self.model, x, y, yaw, covariance, out=held))
        self._forget_doubt()
        self._started = "the initial pose"

    def _forget_doubt(self) -> None:
        """A prior given (or none: uniform) is the belief's whole answer: no new mode in
        it, and none to compare the next update's with."""
        self.doubt, self._mode = 0.0, None
        self.doubt_cause = failure.Doubt.NONE
        self.astray = failure.Astray.none()

    def _hold(self, belief: FloatArray) -> None:
        """Take ``belief`` over the whole grid as the belief: with belief_floor > 0 without
        its states below the floor, held in the windows of the rest."""
        belief, dropped = window.drop_below(belief, self._floor)
        self._take(HeldBelief.windowed(belief) if self._floor > 0 else HeldBelief.whole(belief),
                   dropped)

    def _take(self, held: HeldBelief, dropped: float) -> None:
        """Take ``held`` as the belief (``dropped``: the probability its making left out),
        the last scan forgotten (an update notes its own after)."""
        self._held, self.last_dropped = held, dropped
        self._last_scan = None

    def _hold_windows(self, correction: window.Correction) -> None:
        """Take a windowed correction's posterior as the belief, without its states below
        the floor (at most floor x states, noted in ``last_dropped``), and note the
        windows of what is left."""
        parts, (ks, rs, cs, kept) = correction.parts, correction.kept
        top = max(max(float(part.max()) for part in parts), float(kept.max(initial=0.0)))
        threshold = min(self._floor, top)    # the largest state is never dropped
        dropped = sum(window.zero_below(part, threshold) for part in parts)
        small = kept < threshold
        dropped += float(kept[small].sum())
        ks, rs, cs, kept = ks[~small], rs[~small], cs[~small], kept[~small]
        remaining = sum(float(part.sum()) for part in parts) + float(kept.sum())
        footprint = np.zeros(self.model.free.shape, dtype=bool)
        for part, (r0, r1, c0, c1) in zip(parts, correction.boxes):
            part /= remaining
            footprint[r0:r1, c0:c1] = part.any(axis=0)
        footprint[rs, cs] = True
        # The correction's windows are the grown ones: the new ones are its support's.
        corrected = HeldBelief(self.model.shape, correction.boxes, parts)
        self._held = corrected.regrouped(window.support_boxes(footprint),
                                         (ks, rs, cs, kept / remaining))
        self.last_dropped = dropped + correction.left_out

    def on_odometry(self, pose: Pose, stamp_ns: int | None = None) -> OdometryStep:
        """Follow odometry: how the message was taken (see ``OdometryStep``)."""
        pose = check_pose("pose", pose)
        stamp_ns = _stamp(stamp_ns)
        if stamp_ns is not None and self._history and stamp_ns == self._history[-1][0]:
            return OdometryStep.REPEATED_STAMP
        latest = self._latest
        if latest is not None and math.hypot(pose[0] - latest[0],
                                             pose[1] - latest[1]) > self._max_jump:
            # What was moved before the jump is lost with it; follow on from here.
            self._history.clear()
            self._latest = pose
            if self._reference is not None:
                self._reference = pose
            self._remember(pose, stamp_ns)
            return OdometryStep.JUMP
        self._latest = pose
        self._remember(pose, stamp_ns)
        return OdometryStep.TAKEN

    def _remember(self, pose: Pose, stamp_ns: int | None) -> None:
        if stamp_ns is not None and (not self._history or stamp_ns >= self._history[-1][0]):
            self._history.append((stamp_ns, pose))

    def odometry_covers(self, stamp_ns: int) -> bool:
        """Whether odometry up to ``stamp_ns`` (a scan's time) has come in."""
        stamp_ns = check_integer("stamp_ns", stamp_ns)
        return bool(self._history) and self._history[-1][0] >= stamp_ns

    def _pose_for(self, stamp_ns: int | None, odometry: Pose | None) -> Pose | None:
        if odometry is not None:
            return check_pose("odometry", odometry)
        return self._odometry_at(_stamp(stamp_ns))

    def odometry_at(self, stamp_ns: int | None) -> Pose | None:
        """The odometry pose an update at ``stamp_ns`` predicts to (None: none yet)."""
        return self._odometry_at(_stamp(stamp_ns))

    def set_laser_pose(self, laser_pose: tuple[float, float, float]) -> None:
        """Score scans from this mount from now on (one read from the tf tree at the first
        scan); the belief is unchanged."""
        model = self.model
        if tuple(model.laser_pose) == tuple(mounting_pose(laser_pose)):
            return
        fit = model.scan_fit
        self.model = dataclasses.replace(
            model, laser_pose=laser_pose,
            scan_fit=None if fit is None else dataclasses.replace(fit, laser_pose=laser_pose))

    def _odometry_at(self, stamp_ns: int | None) -> Pose | None:
        """The latest odometry pose at or before ``stamp_ns`` (the latest one, without)."""
        if stamp_ns is None or not self._history:
            return self._latest
        index = bisect_right([stamp for stamp, _ in self._history], stamp_ns)
        return self._history[index - 1][1] if index else None

    def due(self, stamp_ns: int | None = None, odometry: Pose | None = None) -> bool:
        """Whether a scan taken at ``stamp_ns`` updates the filter: the first once odometry
        is there, later ones after enough motion since the last update. ``odometry``: the
        odometry pose at the scan's time where the caller knows it (tf's, interpolated),
        else the latest followed at or before it."""
        pose = self._pose_for(stamp_ns, odometry)
        if pose is None:
            return False
        if self._reference is None:
            return True
        dx = pose[0] - self._reference[0]
        dy = pose[1] - self._reference[1]
        turned = abs(math.remainder(pose[2] - self._reference[2], 2 * math.pi))
        return math.hypot(dx, dy) >= self._min_d or turned >= self._min_a

    def update(self, ranges: FloatArray, angles: FloatArray,
               stamp_ns: int | None = None, odometry: Pose | None = None) -> None:
        """Predict with the odometry from the last update to the scan's time (``odometry``
        as in ``due``), correct with the scan: the beams to score, without the readings of
        no return (see ``laser.check_scan``: a NaN, infinite or negative range is refused)."""
        ranges, angles = check_scan(ranges, angles)
        pose = self._pose_for(stamp_ns, odometry)
        if pose is None:
            raise InvalidInputError(
                "stamp_ns: no odometry yet: the motion since the last update is unknown")
        delta = None if self._reference is None else odometry_delta(self._reference, pose)
        weight = 1.0 if self._independent_beams is None else \
            scan_weight(self._independent_beams, ranges.size)
        increment = None if delta is None or self._mode is None \
            or self._astray_probability == 0.0 else failure.Increment(
                self._mode, failure.moved(self._mode, delta), self._astray_probability)
        astray = failure.Astray.none()
        if self._floor > 0.0:
            correction = self._windowed_step(ranges, angles, delta, weight, increment)
            self._hold_windows(correction)
            log_evidence, kidnapped = correction.log_evidence, correction.kidnapped
            astray = correction.astray or astray
        else:
            posterior, log_evidence, kidnapped = self._dense_step(ranges, angles, delta,
                                                                  weight)
            self._hold(posterior)
        self.log_evidence = log_evidence
        mode = self._most_likely_pose()
        jumped = delta is not None and self._mode is not None and failure.jumped(
            self.model, self.noise, self._mode, delta, mode)
        doubt = failure.judged(self.doubt, kidnapped, jumped)
        if doubt - self.doubt * (1.0 - failure.RECOVERY) > self.doubt * (1.0 - failure.RECOVERY):
            # What this update brought outweighs what is left of the earlier doubt.
            self.doubt_cause = failure.Doubt.JUMPED if jumped else failure.Doubt.FOUND_ANYWHERE
        self.doubt = doubt
        self.astray = self.astray.faded(astray, delta)
        self._mode = mode
        self._reference = pose
        self._last_scan = (ranges, angles)
        self.updates += 1

    def _dense_step(self, ranges: FloatArray, angles: FloatArray,
                    delta: tuple[float, float, float] | None,
                    weight: float) -> tuple[FloatArray, float, float]:
        """The exact filter over the whole grid: posterior, log evidence and the kidnap
        share's posterior probability."""
        belief = self.belief
        if delta is not None:
            belief = _predict(belief, self.model, delta, self.noise)
        if self._kidnap <= 0.0:
            posterior, log_evidence = _correct_scan(
                belief, self.model, ranges, angles, weight=weight,
                box=window.full_box(self.model))
            return posterior, log_evidence, 0.0
        # The robot may have been carried anywhere: a little of the belief everywhere,
        # so a kidnapped robot is found again by the scans alone.
        belief = (1.0 - self._kidnap) * belief + \
            (self._kidnap / self._free_states) * self.model.free

        def log_likelihood() -> FloatArray:
            total = _scan_log_likelihood(self.model, ranges, angles, True,
                                         window.full_box(self.model))
            return np.multiply(total, weight, out=total) if weight != 1.0 else total

        scores = log_likelihood()
        free = np.broadcast_to(self.model.free, scores.shape)
        peak = float(np.max(scores, where=free, initial=-math.inf))
        # log of the kidnap share's part of the evidence: (kidnap / free states) x the sum
        # of the likelihood over the free states.
        share = math.log(self._kidnap / self._free_states) + peak + math.log(
            float(np.sum(np.exp(scores - peak), where=free)))
        posterior, log_evidence = _correct_in(scores, belief, log_likelihood)
        return posterior, log_evidence, min(1.0, math.exp(share - log_evidence))

    def _windowed_step(self, ranges: FloatArray, angles: FloatArray,
                       delta: tuple[float, float, float] | None,
                       weight: float,
                       increment: failure.Increment | None = None) -> window.Correction:
        """The steps over the windows: each grown by what the motion reaches (those that
        then overlap joined), predicted on its own and normalized together, then
        corrected together (window.correct_boxes)."""
        held = self._windows
        boxes = held.boxes if delta is None else window.disjoint(
            [window.grown_box(box, self.model, delta, self.noise,
                              np.flatnonzero(part.any(axis=(1, 2))))
             for box, part in held.windows()])
        if delta is None:
            # The correction only reads its prior: a start's uniform one as it is held.
            priors = list(held.parts)
        else:
            # Each window with the kernels of the whole grid's size: numpy's on a small
            # window cost more than the compiled ones (a pass per heading).
            spreads = [_spread(*self._window(box)[::-1], delta, self.noise,
                               grid_states=_states(self.model)) for box in boxes]
            total = sum(left for _, left in spreads)
            priors = [_normalized(spread, total) for spread, _ in spreads]
        return window.correct_boxes(priors, boxes, self.model, ranges, angles, weight,
                                    self._kidnap, self._floor, phase=self.updates,
                                    increment=increment)

    @property
    def window_states(self) -> int:
        """The states the next update starts from: its windows', all headings."""
        return self._windows.states

    @property
    def held_bytes(self) -> int:
        """The memory the belief holds: its windows' (with belief_floor a tracked robot's
        few square metres, not the building)."""
        return self._windows.nbytes

    def _window(self, box: window.Box) -> tuple[GridModel, FloatArray]:
        """The map and the belief within ``box`` (the belief held where ``box`` is one of
        its windows: the steps only read it)."""
        model = self.model if box == window.full_box(self.model) else window.crop(self.model, box)
        return model, self._windows.within_box(box)

    def estimate(self, radius: float, angle: float) -> Estimate:
        """The most likely pose (belief.refined_pose of the most likely state), the
        covariance around it, and the probability within ``radius`` (m) and ``angle``
        (rad) of it: sums over the windows; both for a belief that may have lost the
        robot (``lost_probability``): the quality that much lower, the covariance the
        mixture's with the robot anywhere."""
        radius, angle = check_non_negative("radius", radius), check_non_negative("angle", angle)
        model = self.model
        windows = list(self._windows.windows())
        box, belief = max(windows, key=lambda pair: float(pair[1].max()))
        pose = _refined_pose(belief, model, _most_likely_state(belief), box)
        estimate = self._around(windows, box, belief, pose, radius, angle)
        if model.scan_fit is not None and self._last_scan is not None:
            # The belief's figures stay those of its own pose; the published pose is the
            # scan's best fit within a state cell and a heading bin of it.
            fitted = scan_fit.fitted_pose(model.scan_fit, pose, *self._last_scan,
                                          model.resolution, model.bin_width)
            estimate = Estimate(fitted, estimate.covariance, estimate.quality)
        astray = self.astray
        if astray.mass > 0.0:
            estimate = Estimate(estimate.pose,
                                (1.0 - astray.mass) * estimate.covariance
                                + astray.about(estimate.pose),
                                (1.0 - astray.mass) * estimate.quality
                                + astray.near(estimate.pose, radius, angle))
        doubt = 1.0 - (1.0 - self.doubt) * (1.0 - self.last_dropped)
        if doubt == 0.0:
            return estimate
        return Estimate(estimate.pose,
                        (1.0 - doubt) * estimate.covariance
                        + doubt * failure.anywhere_around(self._anywhere, estimate.pose),
                        (1.0 - doubt) * estimate.quality)

    def standing(self, estimate: Estimate, radius: float,
                 angle: float) -> tuple[failure.Standing, str]:
        """Localized, uncertain or lost (``failure.standing_of`` the published quality of
        ``estimate``, made with ``radius`` and ``angle``), and why, in words."""
        state = failure.standing_of(estimate.quality)
        near = f"within {radius:g} m and {math.degrees(angle):g} deg of the pose"
        if state is failure.Standing.LOCALIZED:
            return state, f"{estimate.quality:.2f} of the belief {near}"
        if self._mode is None:
            return state, f"no scan since {self._started}"
        doubts = {self.doubt_cause.value: self.doubt,
                  "the scan fits a place near the predicted or the last pose better than "
                  "the tracked one: the odometry may have failed": self.astray.mass,
                  "belief_floor dropped part of the belief": self.last_dropped}
        reason, share = max(doubts.items(), key=lambda pair: pair[1])
        if share < 0.5 * (1.0 - estimate.quality):
            reason = f"the belief is spread: {estimate.quality:.2f} of it {near}"
        return state, f"{reason} (lost_probability {self.lost_probability:.2f})"

    def _most_likely_pose(self) -> Pose:
        """The belief's mean around its most likely state (the pose ``estimate`` refines)."""
        windows = self._windows.windows()
        box, belief = max(windows, key=lambda pair: float(pair[1].max()))
        return _refined_pose(belief, self.model, _most_likely_state(belief), box)

    @property
    def lost_probability(self) -> float:
        """The probability that the most likely place does not hold the robot: the doubt
        on it (grid/failure.py), that the odometry failed (``astray``), or that the robot
        was in what belief_floor dropped at the last update."""
        return 1.0 - (1.0 - self.doubt) * (1.0 - self.last_dropped) * (1.0 - self.astray.mass)

    def _around(self, windows: list, box: window.Box, belief: FloatArray, pose: Pose,
                radius: float, angle: float) -> Estimate:
        model = self.model
        if len(windows) == 1:
            return Estimate(pose, _covariance_around(belief, model, pose, box),
                            _mass_near(belief, model, pose, radius, angle, box))
        # Each window's second moment about the pose carries the grid's quantization
        # variance once: counted once in the sum.
        quantization = np.diag([model.resolution ** 2 / 12] * 2 + [model.bin_width ** 2 / 12])
        covariance = quantization + sum(
            _covariance_around(part, model, pose, where) - quantization
            for where, part in windows)
        quality = sum(_mass_near(part, model, pose, radius, angle, where)
                      for where, part in windows)
        return Estimate(pose, covariance, float(quality))

    def most_likely_states(self, count: int) -> list[tuple[Pose, float]]:
        """The ``count`` most probable states with their probability, most probable first
        (the poses of their cells and headings): what RViz's particle cloud shows of a
        particle filter."""
        count = check_integer("count", count)
        if count < 0:
            raise InvalidInputError(f"count: expected an integer >= 0, got {count}")
        found: list[tuple[float, Pose]] = []
        for box, part in self._windows.windows():
            # A heading layer at a time: a start's uniform belief repeats one layer
            # (``_uniform``), which a flat view of the whole would copy.
            for k, layer in enumerate(part):
                flat = layer.reshape(-1)
                n = min(count, flat.size)
                if n == 0:
                    continue
                for index in np.argpartition(flat, flat.size - n)[flat.size - n:]:
                    if flat[index] > 0.0:
                        i, j = (int(v) for v in np.unravel_index(index, layer.shape))
                        found.append((float(flat[index]),
                                      _pose_of(self.model, (k, i, j), box)))
        found.sort(key=lambda pair: -pair[0])
        return [(pose, p) for p, pose in found[:count]]

    def belief_map(self) -> np.ndarray:
        windows = list(self._windows.windows())
        peak = max(float(part.max()) for _, part in windows)
        picture = np.zeros(self.model.free.shape, dtype=np.int8)
        for (r0, r1, c0, c1), part in windows:
            top = part.max(axis=0)
            picture[r0:r1, c0:c1] = np.rint(100.0 * top / peak).astype(np.int8)
        return picture

    def entropy_bits(self) -> float:
        return float(sum(_entropy_bits(part) for _, part in self._windows.windows())) + 0.0


def _stamp(stamp_ns: int | None) -> int | None:
    return None if stamp_ns is None else check_integer("stamp_ns", stamp_ns)


def _at_least_zero(name: str, value: float) -> float:
    """A number >= 0, inf included (never, for a threshold)."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        number = math.nan
    if not number >= 0.0 or isinstance(value, (str, bytes)):
        raise InvalidInputError(f"{name}: expected a number >= 0, got {short(value)}")
    return number
