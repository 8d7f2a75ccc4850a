"""Occupancy grid mapping with known poses (Probabilistic Robotics 9.2, log-odds form).

Each cell keeps l = log(p / (1 - p)) of being occupied, 0 at first. For every
scan taken at a known pose, each beam that returned (a range below the sensor's
maximum) adds ``hit`` to the cell its end point lies in, and ``miss`` to every
cell the beam crossed on the way (each cell once per scan, the end points' cells
not). Beams without a return tell nothing here: where a laser saw nothing within
its range, a glass wall or open space cannot be told apart.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from estimation_nodes.core.grid.occupancy import FREE, OCCUPIED, UNKNOWN, OccupancyMap
from estimation_nodes.core.validation import FloatArray


def log_odds(probability: float) -> float:
    return math.log(probability / (1.0 - probability))


@dataclass(frozen=True)
class MappingModel:
    """The inverse sensor model: the log odds a hit and a miss add, the bound that keeps a
    cell revisable, and the probabilities above and below which a cell is occupied or
    free in the map."""

    resolution: float
    hit: float = log_odds(0.7)
    miss: float = log_odds(0.4)
    bound: float = 20.0
    occupied_above: float = 0.65
    free_below: float = 0.25

    def __post_init__(self) -> None:
        if not (math.isfinite(self.resolution) and self.resolution > 0):
            raise ValueError(f"resolution: expected a finite value > 0, got {self.resolution}")
        if not (self.hit > 0 > self.miss):
            raise ValueError("hit and miss: a hit must raise the log odds and a miss lower it")


class OccupancyGridMapper:
    """A log-odds grid over a square that grows as scans reach further."""

    def __init__(self, model: MappingModel) -> None:
        self.model = model
        self._origin = np.zeros(2)          # (x, y) of cell (0, 0)'s corner
        self._log_odds = np.zeros((0, 0))   # rows along y

    def add_scan(self, pose: tuple[float, float, float], ranges: FloatArray,
                 angles: FloatArray, range_max: float) -> None:
        """One scan taken from the sensor pose ``pose`` (x, y, heading); ranges at or above
        ``range_max``, below 0, or not finite are no return."""
        ranges = np.asarray(ranges, dtype=np.float64)
        angles = np.asarray(angles, dtype=np.float64)
        if ranges.shape != angles.shape or ranges.ndim != 1:
            raise ValueError(f"ranges and angles: expected two 1-D arrays of one length, got "
                             f"{ranges.shape} and {angles.shape}")
        if not all(math.isfinite(v) for v in pose):
            raise ValueError(f"pose: expected finite numbers, got {list(pose)}")
        returned = np.isfinite(ranges) & (ranges >= 0) & (ranges < range_max)
        ranges, angles = ranges[returned], angles[returned]
        if ranges.size == 0:
            return
        directions = pose[2] + angles
        ends = np.column_stack([pose[0] + ranges * np.cos(directions),
                                pose[1] + ranges * np.sin(directions)])
        self._cover(np.vstack([ends, [pose[:2]]]))
        step = self.model.resolution / 2
        # Points every half cell along each beam, short of its end point.
        counts = np.maximum((ranges / step).astype(np.int64), 1)
        beam = np.repeat(np.arange(ranges.size), counts)
        along = (np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)) * step
        crossed = np.column_stack([pose[0] + along * np.cos(directions[beam]),
                                   pose[1] + along * np.sin(directions[beam])])
        hit_cells = np.unique(self._cells(ends))
        missed = np.setdiff1d(np.unique(self._cells(crossed)), hit_cells, assume_unique=True)
        flat = self._log_odds.reshape(-1)
        flat[missed] += self.model.miss
        flat[hit_cells] += self.model.hit
        np.clip(flat, -self.model.bound, self.model.bound, out=flat)

    def _cells(self, points: np.ndarray) -> np.ndarray:
        index = np.floor((points - self._origin) / self.model.resolution).astype(np.int64)
        return index[:, 1] * self._log_odds.shape[1] + index[:, 0]

    def _cover(self, points: np.ndarray) -> None:
        """Grow the grid (in whole blocks of cells) so that it holds ``points``."""
        resolution = self.model.resolution
        rows, cols = self._log_odds.shape
        low = points.min(axis=0) - resolution
        high = points.max(axis=0) + resolution
        if rows and (low >= self._origin).all() \
                and (high < self._origin + resolution * np.array([cols, rows])).all():
            return
        margin = 64 * resolution
        if rows:
            low = np.minimum(low - margin, self._origin)
            high = np.maximum(high + margin, self._origin + resolution * np.array([cols, rows]))
        origin = np.floor(low / resolution) * resolution
        shape = np.ceil((high - origin) / resolution).astype(np.int64) + 1
        grown = np.zeros((shape[1], shape[0]))
        if rows:
            shift = np.rint((self._origin - origin) / resolution).astype(np.int64)
            grown[shift[1]:shift[1] + rows, shift[0]:shift[0] + cols] = self._log_odds
        self._origin, self._log_odds = origin, grown

    def occupancy(self) -> OccupancyMap:
        """The map, cropped to the cells any beam reached: OCCUPIED, FREE or UNKNOWN."""
        if self._log_odds.size == 0:
            raise ValueError("no scan with a return was added: the map is empty")
        seen = self._log_odds != 0
        rows = np.flatnonzero(seen.any(axis=1))
        cols = np.flatnonzero(seen.any(axis=0))
        block = self._log_odds[rows[0]:rows[-1] + 1, cols[0]:cols[-1] + 1]
        probability = 1.0 - 1.0 / (1.0 + np.exp(block))
        cells = np.full(block.shape, UNKNOWN, dtype=np.int8)
        cells[(block != 0) & (probability < self.model.free_below)] = FREE
        cells[probability > self.model.occupied_above] = OCCUPIED
        origin = self._origin + self.model.resolution * np.array([cols[0], rows[0]])
        return OccupancyMap(cells, self.model.resolution, (float(origin[0]), float(origin[1])))
