"""Maps: map_server's YAML + image format and OccupancyGrid values to grid models.

A map file is what nav2's map_server reads: a YAML file with ``image``
(PGM or PNG, relative to the YAML file), ``resolution`` (m per pixel),
``origin`` ([x, y, yaw] of the lower-left pixel), ``negate``,
``occupied_thresh``, ``free_thresh`` and ``mode`` (trinary, scale or raw).
Each bad field ends with a MapError naming it.

The localizer's state grid is the map reduced by an integer factor to its
``resolution``: a state cell is free when every map cell in it is free, and
its likelihood field is the distance from the cell to the nearest occupied
map cell (an exact Euclidean distance transform, scipy.ndimage), capped at
``max_distance``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from estimation_nodes.core.errors import InvalidInputError
from estimation_nodes.core.grid.steps import GridModel
from estimation_nodes.core.validation import (
    as_real_array,
    check_integer,
    check_non_negative,
    check_positive,
)

#: OccupancyGrid cell values (nav_msgs): free, occupied, unknown.
FREE, OCCUPIED, UNKNOWN = 0, 100, -1


class MapError(ValueError):
    """A map that cannot be used; the message names the field and says why."""


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


@dataclass(frozen=True)
class SensorField:
    """The likelihood-field model's parameters (Probabilistic Robotics 6.4; AMCL's names)."""

    z_hit: float = 0.5
    z_rand: float = 0.5
    sigma_hit: float = 0.2
    max_range: float = 12.0
    max_distance: float = 2.0

    def __post_init__(self) -> None:
        for name in ("z_hit", "z_rand"):
            object.__setattr__(self, name, check_non_negative(name, getattr(self, name)))
        for name in ("sigma_hit", "max_range", "max_distance"):
            object.__setattr__(self, name, check_positive(name, getattr(self, name)))
        if not self.z_hit + self.z_rand > 0:
            raise InvalidInputError("z_hit, z_rand: expected at least one > 0, got two 0s")


def find_map_file(name: str) -> Path:
    """``name`` as given when it exists (absolute, or relative to the working folder),
    otherwise one of the package's maps (``office.yaml``, ``maps/office.yaml``)."""
    from estimation_nodes.params.installed import package_file

    given = Path(name)
    if given.is_file() or given.is_absolute():
        return given
    shipped = package_file(given.name if given.parent.name == "maps" else name, "maps")
    return shipped if shipped is not None else given


def read_map_file(path: Path) -> OccupancyMap:
    """A map_server map (YAML + image) as an OccupancyMap; a relative name not found from
    the working folder is looked up among the package's maps."""
    path = find_map_file(str(path))
    try:
        spec = yaml.safe_load(Path(path).read_text(encoding="utf-8"))
    except OSError as error:
        raise MapError(f"map_file: cannot read {path}: {error.strerror}") from None
    except yaml.YAMLError as error:
        raise MapError(f"map_file: {path} is not valid YAML: {error}") from None
    if not isinstance(spec, dict):
        raise MapError(f"map_file: {path}: expected a mapping with image, resolution, origin")
    image = _field(spec, "image", str)
    resolution = float(_field(spec, "resolution", (int, float)))
    origin = _field(spec, "origin", list)
    if len(origin) != 3 or not all(isinstance(v, (int, float)) for v in origin):
        raise MapError(f"origin: expected [x, y, yaw], got {origin}")
    if not all(math.isfinite(v) for v in origin):
        raise MapError(f"origin: expected finite numbers, got {origin}")
    if origin[2] != 0:
        raise MapError(f"origin: a rotated map (yaw {origin[2]}) is not supported; "
                       f"rotate the image instead")
    pixels = _read_image(Path(path).parent / image)
    cells = occupancy_from_pixels(
        pixels, negate=bool(spec.get("negate", 0)),
        occupied_thresh=float(spec.get("occupied_thresh", 0.65)),
        free_thresh=float(spec.get("free_thresh", 0.25)), mode=str(spec.get("mode", "trinary")))
    return OccupancyMap(cells, resolution, (float(origin[0]), float(origin[1])))


def _field(spec: dict, name: str, kind) -> Any:
    if name not in spec:
        raise MapError(f"{name}: missing from the map file")
    value = spec[name]
    if not isinstance(value, kind) or isinstance(value, bool):
        raise MapError(f"{name}: unexpected value {value!r}")
    return value


def _read_image(path: Path) -> np.ndarray:
    """The image's grey levels (0..255), the image's top row first."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as picture:
            if picture.mode in ("RGBA", "LA"):
                # map_server: a fully transparent pixel is unknown; keep alpha apart.
                grey = np.asarray(picture.convert("LA"), dtype=np.float64)
                levels, alpha = grey[..., 0], grey[..., 1]
                return np.where(alpha == 0, np.nan, levels)
            return np.asarray(picture.convert("L"), dtype=np.float64)
    except FileNotFoundError:
        raise MapError(f"image: {path} does not exist") from None
    except (UnidentifiedImageError, OSError) as error:
        raise MapError(f"image: cannot read {path}: {error}") from None


def occupancy_from_pixels(pixels: np.ndarray, negate: bool, occupied_thresh: float,
                          free_thresh: float, mode: str) -> np.ndarray:
    """Grey levels (top row first) to OccupancyGrid values (row 0 at the bottom), as
    map_server does: p = (255 - v) / 255 (v / 255 when negated)."""
    if not 0 <= free_thresh < occupied_thresh <= 1:
        raise MapError(f"free_thresh, occupied_thresh: expected 0 <= free < occupied <= 1, "
                       f"got {free_thresh} and {occupied_thresh}")
    if mode not in ("trinary", "scale", "raw"):
        raise MapError(f"mode: expected trinary, scale or raw, got {mode!r}")
    flipped = pixels[::-1]
    unknown = np.isnan(flipped)
    levels = np.nan_to_num(flipped)
    if mode == "raw":
        cells = np.clip(levels, -1, 100)
        return np.where(unknown, UNKNOWN, cells).astype(np.int8)
    p = levels / 255.0 if negate else (255.0 - levels) / 255.0
    cells = np.full(p.shape, UNKNOWN, dtype=np.int8)
    cells[p > occupied_thresh] = OCCUPIED
    cells[p < free_thresh] = FREE
    if mode == "scale":
        between = (p >= free_thresh) & (p <= occupied_thresh)
        scaled = np.rint(99 * (p - free_thresh) / (occupied_thresh - free_thresh))
        cells[between] = scaled[between].astype(np.int8)
    cells[unknown] = UNKNOWN
    return cells


def grid_model(occupancy: OccupancyMap, resolution: float, heading_bins: int,
               sensor: SensorField, max_states: int) -> GridModel:
    """The localizer's state grid and likelihood field for ``occupancy``."""
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
    distance = _distance_to_obstacles(cells, occupancy.resolution, sensor.max_distance)
    nearest = distance.reshape(rows, factor, cols, factor).min(axis=(1, 3))
    return GridModel(free=free, log_field=log_field(nearest, sensor),
                     log_outside=float(log_field(np.array(sensor.max_distance), sensor)),
                     resolution=resolution, origin=occupancy.origin,
                     heading_bins=heading_bins)


def log_field(distance: np.ndarray, sensor: SensorField) -> np.ndarray:
    """log(z_hit exp(-d^2 / 2 sigma^2) + z_rand / max_range): a beam ending ``distance``
    from the nearest obstacle (AMCL's likelihood field)."""
    distance = as_real_array("distance", distance)
    if not np.all(distance >= 0):   # NaN fails too
        raise InvalidInputError("distance: expected distances >= 0 (inf: no obstacle)")
    with np.errstate(over="ignore"):   # a huge distance is exp(-inf) = 0: no hit
        hit = sensor.z_hit * np.exp(-0.5 * (distance / sensor.sigma_hit) ** 2)
    return np.log(hit + sensor.z_rand / sensor.max_range)


def _distance_to_obstacles(cells: np.ndarray, resolution: float,
                           max_distance: float) -> np.ndarray:
    from scipy.ndimage import distance_transform_edt

    occupied = cells >= OCCUPIED
    if not occupied.any():
        return np.full(cells.shape, max_distance)
    return np.minimum(distance_transform_edt(~occupied) * resolution, max_distance)


def sensor_field(values) -> SensorField:
    """The likelihood field's parameters from a node's values (GRID_MODEL_SPECS)."""
    return SensorField(z_hit=values["laser_z_hit"], z_rand=values["laser_z_rand"],
                       sigma_hit=values["laser_sigma_hit"],
                       max_range=values["laser_max_range"],
                       max_distance=values["laser_likelihood_max_dist"])


def odometry_noise(values):
    from estimation_nodes.core.grid.steps import OdometryNoise

    return OdometryNoise(alpha1=values["alpha1"], alpha2=values["alpha2"],
                         alpha3=values["alpha3"], alpha4=values["alpha4"])


def planar_world(occupancy: OccupancyMap):
    """The simulated robot's world at the map's resolution: occupied cells stop beams;
    the clearance keeps it off obstacles and out of unknown space."""
    from scipy.ndimage import distance_transform_edt

    from estimation_nodes.core.sim.planar import PlanarWorld

    occupied = occupancy.cells >= OCCUPIED
    blocked = occupied | (occupancy.cells == UNKNOWN)
    clearance = distance_transform_edt(~blocked) * occupancy.resolution
    return PlanarWorld(occupied=occupied, clearance=clearance,
                       resolution=occupancy.resolution, origin=occupancy.origin)


def occupancy_from_message(width: int, height: int, resolution: float,
                           origin: tuple[float, float, float], data) -> OccupancyMap:
    """An OccupancyGrid's fields as an OccupancyMap; a size that does not match its data,
    or a rotated origin, is a MapError."""
    cells = np.frombuffer(bytes(np.asarray(data, dtype=np.int8).tobytes()), dtype=np.int8)
    if width * height != cells.size or width <= 0 or height <= 0:
        raise MapError(f"map: width x height = {width} x {height} does not match "
                       f"{cells.size} cells of data")
    if not all(math.isfinite(v) for v in origin):
        raise MapError(f"origin: expected finite numbers, got {list(origin)}")
    if abs(origin[2]) > 1e-9:
        raise MapError(f"origin: a rotated map (yaw {origin[2]:.3g}) is not supported")
    return OccupancyMap(cells.reshape(height, width).copy(), float(resolution),
                        (float(origin[0]), float(origin[1])))


@dataclass(frozen=True)
class GridLocalizerSettings:
    """The localizer's validated parameters; the map comes from map_file or the topic."""

    sensor: SensorField
    noise: object
    resolution: float
    heading_bins: int
    max_states: int
    #: From map_file, read and reduced at start-up; None: from the map topic.
    map: OccupancyMap | None
    model: GridModel | None

    def model_for(self, occupancy: OccupancyMap) -> GridModel:
        return grid_model(occupancy, self.resolution, self.heading_bins, self.sensor,
                          self.max_states)


def build_grid_localizer_settings(values) -> GridLocalizerSettings:
    """Validate the localizer's parameters; with map_file set, read it and check that it
    makes a state grid within max_states (a MapError names what is wrong)."""
    sensor = sensor_field(values)
    if not values["frame_id"].strip():
        raise ValueError("frame_id: expected a frame name, got an empty string")
    occupancy = read_map_file(Path(values["map_file"])) if values["map_file"] else None
    model = grid_model(occupancy, values["resolution"], values["heading_bins"], sensor,
                       values["max_states"]) if occupancy is not None else None
    return GridLocalizerSettings(sensor, odometry_noise(values), values["resolution"],
                                 values["heading_bins"], values["max_states"], occupancy,
                                 model)
