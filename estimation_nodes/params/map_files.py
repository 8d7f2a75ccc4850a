"""Maps as map_server reads them: its YAML + image format, and OccupancyGrid values.

A map file is what nav2's map_server reads: a YAML file with ``image``
(PGM or PNG, relative to the YAML file), ``resolution`` (m per pixel),
``origin`` ([x, y, yaw] of the lower-left pixel), ``negate``,
``occupied_thresh``, ``free_thresh`` and ``mode`` (trinary, scale or raw).
Each bad field ends with a MapError naming it. The state grid and the
likelihood field computed from a map are the core's (core/grid/likelihood_field.py).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from estimation_nodes.core.errors import MapError
from estimation_nodes.core.grid.occupancy import FREE, OCCUPIED, UNKNOWN, OccupancyMap


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




#: The grey levels map_server's map_saver writes for occupied, free and unknown cells.
PGM_OCCUPIED, PGM_FREE, PGM_UNKNOWN = 0, 254, 205


def write_map_file(stem: Path, occupancy: OccupancyMap) -> Path:
    """``stem``.yaml and ``stem``.pgm in map_server's trinary format, as map_saver writes
    them (its thresholds too: with free_thresh 0.196 the unknown grey 205 reads back as
    unknown, not free); the YAML's path."""
    stem = Path(stem)
    cells = occupancy.cells
    image = np.full(cells.shape, PGM_UNKNOWN, dtype=np.uint8)
    image[cells == FREE] = PGM_FREE
    image[cells >= OCCUPIED] = PGM_OCCUPIED
    pgm = stem.with_suffix(".pgm")
    rows, cols = cells.shape
    # Row 0 of the grid is at the origin, the bottom of the picture.
    pgm.write_bytes(f"P5\n{cols} {rows}\n255\n".encode("ascii") + image[::-1].tobytes())
    yaml_path = stem.with_suffix(".yaml")
    x, y = occupancy.origin
    yaml_path.write_text(
        f"image: {pgm.name}\nmode: trinary\nresolution: {occupancy.resolution!r}\n"
        f"origin: [{x!r}, {y!r}, 0.0]\nnegate: 0\noccupied_thresh: 0.65\n"
        f"free_thresh: 0.196\n", encoding="utf-8")
    return yaml_path
