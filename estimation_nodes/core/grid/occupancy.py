"""An occupancy map as nav_msgs/OccupancyGrid holds it, independent of where it came from
(a map_server file, the map topic, a recording)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from estimation_nodes.core.errors import InvalidInputError, MapError
from estimation_nodes.core.validation import check_positive

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
        cells = np.asarray(self.cells) if isinstance(self.cells, (np.ndarray, list)) else None
        if cells is None or cells.dtype.kind not in "iu":
            raise MapError(f"map: expected a 2-D grid of integer cells, got {self.cells!r:.80}")
        if cells.ndim != 2 or 0 in cells.shape:
            raise MapError(f"map: expected a 2-D grid of cells, got shape {cells.shape}")
        try:
            resolution = check_positive("resolution", self.resolution)
        except InvalidInputError:
            raise MapError(f"resolution: expected a finite value > 0, got {self.resolution!r}") \
                from None
        try:
            origin = tuple(float(v) for v in self.origin)
        except (TypeError, ValueError):
            origin = ()
        if len(origin) != 2 or not all(math.isfinite(v) for v in origin):
            raise MapError(f"origin: expected finite x and y, got {self.origin!r}")
        object.__setattr__(self, "cells", cells)
        object.__setattr__(self, "resolution", resolution)
        object.__setattr__(self, "origin", origin)
