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
(``anywhere_around``), both about the pose. A scan that fits the wrong place as well as
the right one (a corridor whose doors repeat, the odometry wrong along it) renews
nothing: no estimate made from these scans could tell.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

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


def judged(doubt: float, kidnapped: float, jumped: bool) -> float:
    """The doubt after an update: what the update's new mode brought (``kidnapped``, the
    kidnap share's posterior probability; all of it when the most likely state
    ``jumped``), and what is left of the doubt before it."""
    new = 1.0 if jumped else min(max(kidnapped, 0.0), 1.0)
    return new + (1.0 - new) * doubt * (1.0 - RECOVERY)


def jumped(model: GridModel, noise: OdometryNoise, before: Pose,
           delta: tuple[float, float, float], after: Pose) -> bool:
    """Whether ``after`` is beyond the prediction's reach from ``before`` moved by
    ``delta`` (rot1, trans, rot2): further than REACH_SIGMAS of the motion noise and
    REACH_CELLS cells in position, or as many heading bins in heading."""
    rot1, trans, rot2 = delta
    x = before[0] + trans * math.cos(before[2] + rot1)
    y = before[1] + trans * math.sin(before[2] + rot1)
    yaw = before[2] + rot1 + rot2
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
