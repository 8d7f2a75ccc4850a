"""An occupancy map as nav_msgs/OccupancyGrid holds it, independent of where it came from
(a map_server file, the map topic, a recording)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from estimation_nodes.core.errors import MapError

#: OccupancyGrid cell values (nav_msgs): free, occupied, unknown.
FREE, OCCUPIED, UNKNOWN = 0, 100, -1


@dataclass(frozen=True)
class OccupancyMap:
    """An occupancy grid as nav_msgs/OccupancyGrid holds it: ``cells`` (H, W) int8 of
    FREE, OCCUPIED, UNKNOWN (or 1..99), row 0 at the origin (the image's last row)."""

    cells: np.ndarray
    resolution: float
    origin: tuple[float, float]

    def __post_init__(self) -> None:
        if self.cells.ndim != 2 or 0 in self.cells.shape:
            raise MapError(f"map: expected a 2-D grid of cells, got shape {self.cells.shape}")
        if not (math.isfinite(self.resolution) and self.resolution > 0):
            raise MapError(f"resolution: expected a finite value > 0, got {self.resolution}")
        if not all(math.isfinite(v) for v in self.origin):
            raise MapError(f"origin: expected finite x and y, got {list(self.origin)}")
