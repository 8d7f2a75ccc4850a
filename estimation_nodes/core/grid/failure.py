"""Whether the belief's most likely place can be trusted: a doubt carried over the updates.

The grid filter's posterior is exact for its model, but on a real robot the model
fails: the odometry runs backwards or slips, people cross the laser, the robot is
carried. The belief's mass near its pose (``localization_quality``) and its covariance
then say nothing of it: when the tracked belief cannot explain a scan, the correction
puts the mass on whatever place explains it least badly, found through the kidnap
share anywhere on the map, and that place, being alone, looks certain (issue 38:
docs/benchmarks.md, "Faults on real logs", has the figures). Two things the filter
knows at each update say that the place is new, not tracked:

- ``kidnapped``: the posterior probability of the kidnap share, the mixture component
  "the robot was carried anywhere since the last update" (the probability the
  correction gave the states through it; 0 without a kidnap share). Where the tracked
  belief explains the scan it is tiny; where the best place came through the share
  alone it is near 1.
- ``jumped``: the most likely state left the reach of the tracked one: it is further
  from the last update's, moved by the odometry, than the prediction spreads (three of
  its standard deviations and two cells, or heading bins): a mode that was not carried
  there by the motion, such as a far window kept from an earlier update's kidnap share.

Either makes the doubt that the published place holds the robot: a place found by one
scan among all the map's is unconfirmed, whatever mass that scan gave it. The doubt
then goes with each update that does not renew it, by RECOVERY a scan: the new mode is
confirmed over several updates before it is published as certain (three, to a doubt of
1/8, from one found through the share alone). In the book's terms it is the
probability of a two-state chain (confirmed, not yet), "not yet" entered with the
probability of the update's new mode and left at RECOVERY per update.

What the localizer publishes takes it in (``GridLocalization.estimate``): the quality
is (1 - doubt) x the belief's mass near the pose, and the covariance the mixture's:
(1 - doubt) x the belief's + doubt x that of the robot anywhere on the free cells
(``anywhere_around``), both about the pose.

The odometry fails more often than the robot is carried off: wheels slip, an encoder
runs backwards, and the prediction then carries the belief to a place the motion noise
cannot leave, where the scans are explained by whatever fits there least badly (a
corridor's repeating doors: issue 38's backwards odometry, its error 1.5 to 2.7 m with a
quality up to 0.92). The model holds a third component for it, ``Astray``: with
ASTRAY_PROBABILITY at each update the odometry failed and the robot is within
ASTRAY_RADIUS_M of where the odometry said it went or of where it was at the last update,
nearer places the likelier (``_astray_places``): the increment that failed may be off by
a slip or mean nothing at all (wheels running backwards, an encoder frozen).
Its posterior is that of any mixture component: the prior share times the scan's
likelihood averaged under that prior, against the tracked belief's evidence: near
nothing where the tracked belief explains the scan as well as the places around it, most
of the mass where a place near it explains it many nats better. The states of the disc
are scored anyway (the kidnap share's lattice, grid/window.py; each to the end only while
its bound could add to the component's mass: ``astray_bounds``); they are not kept in the
belief (a disc of metres in the windows would cost the building): the belief goes on as
the posterior given that the odometry held, and what is published is the mixture's, the
component's mass and second moment taken in (``Astray.about``), faded by RECOVERY at
each update as the doubt.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum

import numpy as np

from estimation_nodes.core.grid.model import GridModel
from estimation_nodes.core.grid.motion import OdometryNoise, _motion_noise
from estimation_nodes.core.validation import FloatArray

Pose = tuple[float, float, float]

#: Of the doubt on a place, the share each update that does not renew it takes away.
RECOVERY = 0.5
#: The prediction's reach in its standard deviations, and in cells (or heading bins)
#: beyond them: a most likely state further from the last one moved by the odometry
#: was not carried there by the motion.
REACH_SIGMAS, REACH_CELLS = 3.0, 2.0
#: The prior probability, at each update, that the odometry failed since the last one
#: and the robot is within ASTRAY_RADIUS_M (m) of the predicted pose or of the last
#: update's (``Increment``). Measured on the
#: fault bench (bench/grid_faults.py), with the prior then around the predicted pose
#: alone: 0.1 left an ACES corridor's backwards odometry published with quality 0.87 at
#: 1.5 m off; 0.3 would say lost on the unfaulted ACES log where its corridors repeat.
ASTRAY_PROBABILITY = 0.25
ASTRAY_RADIUS_M = 8.0
#: Its prior's shape (``_astray_prior``): the distance below which it is as likely as at
#: it, how fast it falls with distance beyond, and the share of it on headings within
#: ASTRAY_TURN_RAD of the predicted one.
ASTRAY_NEAR_M = 0.5
ASTRAY_FALL = 3.0
ASTRAY_TURN_RAD = math.radians(30.0)
ASTRAY_SAME_HEADING = 0.8


class Standing(Enum):
    """What the localizer says of itself (``/diagnostics``), from the quality it publishes
    (the belief's mass near the pose, with every doubt above taken in)."""

    LOCALIZED = "localized"
    UNCERTAIN = "uncertain"
    LOST = "lost"


#: The published quality from which the localizer is localized, and below which it is
#: lost (uncertain between): the quality of nav2-minded consumers' "sure" and "lost"
#: (bench/real_logs.py's confidently wrong takes 0.8).
SURE_QUALITY, LOST_QUALITY = 0.8, 0.5


def standing_of(quality: float) -> Standing:
    if quality >= SURE_QUALITY:
        return Standing.LOCALIZED
    return Standing.UNCERTAIN if quality >= LOST_QUALITY else Standing.LOST


#: Why the most likely place is doubted, by what made the doubt (``Doubt``).
class Doubt(Enum):
    NONE = "none"
    #: The posterior came through the kidnap share: a place found anywhere on the map.
    FOUND_ANYWHERE = "the scan fits a place found anywhere on the map, not yet confirmed"
    #: The most likely state left the prediction's reach.
    JUMPED = "the most likely pose jumped beyond the motion's reach, not yet confirmed"


def judged(doubt: float, kidnapped: float, jumped: bool) -> float:
    """The doubt after an update: what the update's new mode brought (``kidnapped``, the
    kidnap share's posterior probability; all of it when the most likely state
    ``jumped``), and what is left of the doubt before it."""
    new = 1.0 if jumped else min(max(kidnapped, 0.0), 1.0)
    return new + (1.0 - new) * doubt * (1.0 - RECOVERY)


def moved(before: Pose, delta: tuple[float, float, float]) -> Pose:
    """``before`` moved by ``delta`` (rot1, trans, rot2), as the prediction moves it."""
    rot1, trans, rot2 = delta
    return (before[0] + trans * math.cos(before[2] + rot1),
            before[1] + trans * math.sin(before[2] + rot1), before[2] + rot1 + rot2)


def jumped(model: GridModel, noise: OdometryNoise, before: Pose,
           delta: tuple[float, float, float], after: Pose) -> bool:
    """Whether ``after`` is beyond the prediction's reach from ``before`` moved by
    ``delta`` (rot1, trans, rot2): further than REACH_SIGMAS of the motion noise and
    REACH_CELLS cells in position, or as many heading bins in heading."""
    x, y, yaw = moved(before, delta)
    sigma_cells, sigma_bins = _motion_noise(delta, noise, model)
    reach_m = (REACH_SIGMAS * sigma_cells + REACH_CELLS) * model.resolution
    reach_rad = (REACH_SIGMAS * sigma_bins + REACH_CELLS) * model.bin_width
    return bool(math.hypot(after[0] - x, after[1] - y) > reach_m
                or abs(math.remainder(after[2] - yaw, 2 * math.pi)) > reach_rad)


@dataclass(frozen=True)
class Spread:
    """The free cells' centres as a distribution (the robot anywhere on them): their
    mean and covariance in x and y, and the headings."""

    mean: FloatArray
    covariance: FloatArray
    headings: FloatArray


def spread_of(model: GridModel) -> Spread:
    xs, ys = model.cell_centres()
    rows, cols = np.nonzero(model.free)
    points = np.stack([xs[cols], ys[rows]])
    return Spread(points.mean(axis=1), np.cov(points, bias=True), model.headings())


def anywhere_around(spread: Spread, pose: tuple[float, float, float]) -> FloatArray:
    """The second moment of (x, y, yaw) about ``pose`` of the robot anywhere on the free
    cells, at any heading (x and y apart from the heading)."""
    offset = spread.mean - np.asarray(pose[:2])
    moment = np.zeros((3, 3))
    moment[:2, :2] = spread.covariance + np.outer(offset, offset)
    turns = np.remainder(spread.headings - pose[2] + math.pi, 2 * math.pi) - math.pi
    moment[2, 2] = float(np.mean(turns ** 2))
    return moment


#: Of the odometry-failure component, the states kept: those of at least this share of
#: its most probable one (the rest, the disc's far tails, are below any quality).
ASTRAY_KEPT = 1e-6
#: A component of less probability is left out (its second moment, 8 m away at most,
#: then adds below 0.01 m^2 to the covariance).
ASTRAY_NEGLIGIBLE = 1e-4


@dataclass(frozen=True)
class Astray:
    """The robot's place should the odometry have failed (the module's docstring): its
    states (x, y, yaw) and their probabilities (``mass`` in all, the component's
    posterior probability)."""

    x: FloatArray
    y: FloatArray
    yaw: FloatArray
    p: FloatArray

    @staticmethod
    def none() -> "Astray":
        empty = np.zeros(0)
        return Astray(empty, empty, empty, empty)

    @property
    def mass(self) -> float:
        return float(self.p.sum())

    def faded(self, new: "Astray", delta: tuple[float, float, float] | None) -> "Astray":
        """After an update with the motion ``delta`` whose component is ``new``: it, and
        this one moved by ``delta`` in the rest of the probability, faded by RECOVERY (as
        the doubt)."""
        keep = (1.0 - new.mass) * (1.0 - RECOVERY)
        old = self.p * keep
        held = old >= ASTRAY_KEPT * float(old.max(initial=0.0))
        x, y, yaw = self.x[held], self.y[held], self.yaw[held]
        if delta is not None:
            rot1, trans, rot2 = delta
            x, y = x + trans * np.cos(yaw + rot1), y + trans * np.sin(yaw + rot1)
            yaw = yaw + rot1 + rot2
        return Astray(*(np.concatenate(pair) for pair in
                        ((new.x, x), (new.y, y), (new.yaw, yaw), (new.p, old[held]))))

    def _offsets(self, pose: Pose) -> tuple[FloatArray, FloatArray, FloatArray]:
        return (self.x - pose[0], self.y - pose[1],
                np.remainder(self.yaw - pose[2] + math.pi, 2 * math.pi) - math.pi)

    def about(self, pose: Pose) -> FloatArray:
        """The component's second moment of (x, y, yaw) about ``pose``, times its mass."""
        offsets = np.stack(self._offsets(pose))
        return (offsets * self.p) @ offsets.T

    def near(self, pose: Pose, radius: float, angle: float) -> float:
        """The component's probability within ``radius`` and ``angle`` of ``pose``."""
        dx, dy, turn = self._offsets(pose)
        return float(self.p[(np.hypot(dx, dy) <= radius) & (np.abs(turn) <= angle)].sum())


@dataclass(frozen=True)
class Increment:
    """The odometry's increment since the last update, which may have failed: the most
    likely pose at the last update, where the increment moved it (the prediction), and
    the prior probability that it failed."""

    last: Pose
    predicted: Pose
    probability: float = ASTRAY_PROBABILITY


@dataclass(frozen=True)
class Reach:
    """The component's prior over the listed lattice cells, centres (x[n], y[n]):
    ``prior[n]`` (``_astray_places``, half around the increment's predicted pose, half
    around its last one; 0 beyond ASTRAY_RADIUS_M of both), ``cells`` the n with some.
    Made once per update, for the bounds and the component."""

    increment: Increment
    cells: np.ndarray
    prior: FloatArray
    x: FloatArray
    y: FloatArray

    @property
    def probability(self) -> float:
        return self.increment.probability


def reach_of(x: FloatArray, y: FloatArray, increment: Increment) -> Reach:
    """The reach of ``increment`` among the listed cells whose centres are (x[n], y[n])."""
    prior = np.zeros(x.size)
    for centre in (increment.predicted, increment.last):
        dx, dy = x - centre[0], y - centre[1]
        squared = dx * dx
        squared += dy * dy
        cells = np.flatnonzero(squared <= ASTRAY_RADIUS_M ** 2)
        if cells.size:
            prior[cells] += 0.5 * _astray_places(np.sqrt(squared[cells]))
    return Reach(increment, np.flatnonzero(prior), prior, x, y)


#: The component's mass may be understated by at most this (absolute): a lattice state
#: within its reach is scored to the end only while the bound on its log likelihood (its
#: beams so far, every beam left a perfect hit) could give it more (``astray_bounds``).
ASTRAY_UNSCORED = 3e-3


def astray_bounds(reach: Reach, size: int, log_tracked: float) -> FloatArray:
    """Per listed lattice cell (``size`` of them): the log likelihood under which none of
    its states can matter to the component (-inf where every one must be scored; +inf
    beyond its reach), given ``log_tracked``, the log of a lower bound on the rest of
    the mixture's evidence (the windows' weights, before the lattice adds to them).

    A state of heading k at cell n adds P x bearings[k] x places[n] x exp(log
    likelihood) to the component's evidence (``astray_in``; P its prior probability,
    places[n] the cell's share of it); the headings' shares sum to 1, so with every state
    of cell n below the bound b[n] below, the cell's states add less than its allowance,
    ASTRAY_UNSCORED x (1 - P) x exp(log_tracked) x (1 / M + places[n]) / 2 (M: the cells
    within reach). The allowances of the M cells sum to ASTRAY_UNSCORED of the mixture's
    evidence at most: the component's mass, the share of it, is short of the exact one by
    less than ASTRAY_UNSCORED. (Half the allowance spread evenly, half as the prior: each
    cell's bound is within log 2 of the larger of the two ways', the far cells' of the
    even one, the near cells' of the prior's.)"""
    bounds = np.full(size, math.inf)
    if reach.cells.size == 0:
        return bounds
    if not math.isfinite(log_tracked):
        bounds[reach.cells] = -math.inf
        return bounds
    places = reach.prior[reach.cells]
    allowed = math.log(ASTRAY_UNSCORED * (1.0 - reach.probability)
                       / (2.0 * reach.probability))
    bounds[reach.cells] = log_tracked + allowed + np.log1p(1.0 / (reach.cells.size * places))
    return bounds


def astray_in(headings: FloatArray, k: np.ndarray, n: np.ndarray, values: FloatArray,
              tracked: float, reach: Reach, scale: float = 1.0) -> Astray:
    """The odometry-failure component after a correction, from the scan's likelihood at
    the kidnap lattice's states listed: state i, of heading ``headings[k[i]]`` (the
    lattice's, every KIDNAP_STEP-th bin) at the listed cell n[i], has the likelihood
    values[i] x ``scale`` relative to a peak (a state not listed: 0, as one the bound
    left unscored); ``tracked`` the rest of the mixture's evidence on the same scale,
    and ``reach`` the cells around the increment.

    The component's prior over the lattice states within ASTRAY_RADIUS_M of the predicted
    pose or the last one (``_astray_places``, ``_astray_bearings``), half around each: a
    density over each disc as distance ** -ASTRAY_FALL from ASTRAY_NEAR_M on (an error
    of a metre far likelier than one of several: the scans of a long corridor repeat
    every few metres, and an unfaulted log's tracked belief then meets places that fit
    better 4 to 7 m off), its heading within ASTRAY_TURN_RAD of the predicted one with
    ASTRAY_SAME_HEADING of the probability (wheels that slip or run backwards keep the
    heading; a robot carried off does not)."""
    if reach.cells.size == 0:
        return Astray.none()
    bearings = _astray_bearings(headings - reach.increment.predicted[2])
    posterior = values * bearings[k] * reach.prior[n]
    total = float(posterior.sum()) * scale
    if not total > 0.0:
        return Astray.none()
    share = reach.probability * total
    mass = share / (share + (1.0 - reach.probability) * tracked)
    if mass < ASTRAY_NEGLIGIBLE:
        return Astray.none()
    kept = np.flatnonzero(posterior >= ASTRAY_KEPT * float(posterior.max()))
    p = posterior[kept]
    cells = n[kept]
    return Astray(reach.x[cells], reach.y[cells], headings[k[kept]], p * (mass / p.sum()))


def _astray_places(distance: FloatArray) -> FloatArray:
    places = np.maximum(distance, ASTRAY_NEAR_M) ** -ASTRAY_FALL
    return places / places.sum()


def _astray_bearings(turns: FloatArray) -> FloatArray:
    same = np.abs(np.remainder(turns + math.pi, 2 * math.pi) - math.pi) <= ASTRAY_TURN_RAD
    bearings = np.where(same, ASTRAY_SAME_HEADING / max(int(same.sum()), 1),
                        (1.0 - ASTRAY_SAME_HEADING) / max(int((~same).sum()), 1))
    return bearings / bearings.sum()
