"""The likelihood-field sensor model (Probabilistic Robotics 6.4, AMCL's) and the state grid
it is computed on.

The localizer's state grid is the map reduced by an integer factor to its
``resolution``: a state cell is free when every map cell in it is free, and
its likelihood field is the distance from the cell to the nearest occupied
map cell (an exact Euclidean distance transform, scipy.ndimage), capped at
``max_distance``. A scan is scored on the field by laser.py.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimation_nodes.core.errors import InvalidInputError, MapError
from estimation_nodes.core.grid.model import GridModel, mounting_pose
from estimation_nodes.core.grid.occupancy import FREE, OCCUPIED, OccupancyMap
from estimation_nodes.core.grid.scan_fit import FitField
from estimation_nodes.core.validation import (
    as_real_array,
    check_integer,
    check_non_negative,
    check_positive,
)


@dataclass(frozen=True)
class SensorField:
    """The likelihood-field model's parameters (Probabilistic Robotics 6.4; AMCL's names)."""

    z_hit: float
    z_rand: float
    sigma_hit: float
    max_range: float
    max_distance: float
    #: The laser's mounting pose on the robot (x m, y m, yaw rad): base_link -> laser.
    laser_pose: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        object.__setattr__(self, "laser_pose", mounting_pose(self.laser_pose))
        for name in ("z_hit", "z_rand"):
            object.__setattr__(self, name, check_non_negative(name, getattr(self, name)))
        for name in ("sigma_hit", "max_range", "max_distance"):
            object.__setattr__(self, name, check_positive(name, getattr(self, name)))
        if not self.z_hit + self.z_rand > 0:
            raise InvalidInputError("z_hit, z_rand: expected at least one > 0, got two 0s")


def grid_model(occupancy: OccupancyMap, resolution: float, heading_bins: int,
               sensor: SensorField, max_states: int, scan_fit: bool = False) -> GridModel:
    """The localizer's state grid and likelihood field for ``occupancy``; with
    ``scan_fit``, the field at the map's own resolution as well (grid/scan_fit.py)."""
    if not isinstance(occupancy, OccupancyMap) or not isinstance(sensor, SensorField):
        raise MapError(f"occupancy, sensor: expected an OccupancyMap and a SensorField, got "
                       f"{type(occupancy).__name__} and {type(sensor).__name__}")
    try:
        resolution = check_positive("resolution", resolution)
        heading_bins = check_integer("heading_bins", heading_bins)
        max_states = check_integer("max_states", max_states)
    except InvalidInputError as error:
        raise MapError(str(error)) from None
    factor = resolution / occupancy.resolution
    if abs(factor - round(factor)) > 1e-6 or round(factor) < 1:
        raise MapError(f"resolution: expected a whole multiple of the map's "
                       f"{occupancy.resolution} m, got {resolution} m")
    factor = int(round(factor))
    rows, cols = (n // factor for n in occupancy.cells.shape)
    if rows == 0 or cols == 0:
        raise MapError(f"resolution: {resolution} m leaves no state cell on a map of "
                       f"{occupancy.cells.shape[1]} x {occupancy.cells.shape[0]} cells")
    states = rows * cols * heading_bins
    if states > max_states:
        raise MapError(f"max_states: the map makes {states} states ({cols} x {rows} cells x "
                       f"{heading_bins} headings), more than max_states = {max_states}")
    cells = occupancy.cells[:rows * factor, :cols * factor]
    blocks = cells.reshape(rows, factor, cols, factor)
    free = (blocks == FREE).all(axis=(1, 3))
    if not free.any():
        raise MapError("map: no free cell at this resolution")
    distance = distance_to_obstacles(cells, occupancy.resolution, sensor.max_distance)
    nearest = distance.reshape(rows, factor, cols, factor).min(axis=(1, 3))
    log_outside = float(log_field(np.array(sensor.max_distance), sensor))
    fit = FitField(log_field(distance, sensor), log_outside, occupancy.resolution,
                   occupancy.origin, sensor.laser_pose) if scan_fit else None
    return GridModel(free=free, log_field=log_field(nearest, sensor), log_outside=log_outside,
                     resolution=resolution, origin=occupancy.origin,
                     heading_bins=heading_bins, laser_pose=sensor.laser_pose, scan_fit=fit)


def log_field(distance: np.ndarray, sensor: SensorField) -> np.ndarray:
    """log(z_hit exp(-d^2 / 2 sigma^2) + z_rand / max_range): a beam ending ``distance``
    from the nearest obstacle (AMCL's likelihood field)."""
    distance = as_real_array("distance", distance)
    if not np.all(distance >= 0):   # NaN fails too
        raise InvalidInputError("distance: expected distances >= 0 (inf: no obstacle)")
    with np.errstate(over="ignore"):   # a huge distance is exp(-inf) = 0: no hit
        hit = sensor.z_hit * np.exp(-0.5 * (distance / sensor.sigma_hit) ** 2)
    return np.log(hit + sensor.z_rand / sensor.max_range)


def distance_to_obstacles(cells: np.ndarray, resolution: float,
                           max_distance: float) -> np.ndarray:
    from scipy.ndimage import distance_transform_edt

    occupied = cells >= OCCUPIED
    if not occupied.any():
        return np.full(cells.shape, max_distance)
    return np.minimum(distance_transform_edt(~occupied) * resolution, max_distance)
