"""A seeded building the package does not ship, for the localization benchmark.

    python bench/grid/building_map.py OUT_DIR [--seed 11]

30 m x 20 m: two corridors across and one along, rooms between them whose
widths are drawn from a few sizes (so several rooms look alike from inside),
a door in each at a drawn place, and furniture in some. Written in map_server's
format (YAML + PGM, 0.05 m per pixel) as OUT_DIR/building_SEED.yaml. Unlike
maps/generate.py's office and corridor it is made from a seed, so a check of
global localization can run on a map that no test or parameter was tuned on.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

RESOLUTION = 0.05
FREE, OCCUPIED, UNKNOWN = 254, 0, 205
WIDTH_M, HEIGHT_M = 30.0, 20.0
WALL = 0.15
#: Room widths (m) the generator draws from: few sizes, so rooms repeat.
ROOM_WIDTHS = (3.0, 4.0, 4.0, 5.0)
#: The corridors across: (y of the lower wall's inside, y of the upper wall's inside).
CORRIDORS = ((6.0, 8.0), (13.0, 15.0))
#: The corridor along the building, joining the two across.
SPINE = (14.0, 16.0)


class Drawing:
    def __init__(self) -> None:
        self.pixels = np.full((round(HEIGHT_M / RESOLUTION), round(WIDTH_M / RESOLUTION)),
                              UNKNOWN, dtype=np.uint8)

    def box(self, x0: float, y0: float, x1: float, y1: float, value: int) -> None:
        """Fill [x0, x1) x [y0, y1) (m, y up from the bottom edge)."""
        rows = self.pixels.shape[0]
        c0, c1 = round(x0 / RESOLUTION), round(x1 / RESOLUTION)
        r0, r1 = rows - round(y1 / RESOLUTION), rows - round(y0 / RESOLUTION)
        self.pixels[max(r0, 0):max(r1, 0), max(c0, 0):max(c1, 0)] = value


def building(seed: int) -> np.ndarray:
    """The building's pixels (row 0 at the top, as a PGM stores them)."""
    rng = np.random.default_rng(seed)
    d = Drawing()
    d.box(0.0, 0.0, WIDTH_M, HEIGHT_M, OCCUPIED)
    d.box(WALL, WALL, WIDTH_M - WALL, HEIGHT_M - WALL, FREE)
    # Bands of rooms below, between and above the corridors across.
    bands = [(WALL, CORRIDORS[0][0]), (CORRIDORS[0][1], CORRIDORS[1][0]),
             (CORRIDORS[1][1], HEIGHT_M - WALL)]
    for corridor in CORRIDORS:
        d.box(WALL, corridor[0] - WALL, WIDTH_M - WALL, corridor[0], OCCUPIED)
        d.box(WALL, corridor[1], WIDTH_M - WALL, corridor[1] + WALL, OCCUPIED)
    for band, (y0, y1) in enumerate(bands):
        x = WALL
        while x < WIDTH_M - WALL - 2.0:
            if band == 1 and SPINE[0] - 0.5 < x + 2.0 and x < SPINE[1]:
                x = SPINE[1]                  # the corridor along crosses the middle band
                continue
            width = float(rng.choice(ROOM_WIDTHS))
            x1 = min(x + width, WIDTH_M - WALL)
            if band == 1 and x < SPINE[0] < x1:
                x1 = SPINE[0] - WALL
            if x1 - x < 2.0:
                break
            d.box(x1, y0, x1 + WALL, y1, OCCUPIED)           # the wall to the next room
            _door(d, rng, x, x1, y0, y1, band)
            if rng.random() < 0.6:
                _furniture(d, rng, x, x1, y0, y1)
            x = x1 + WALL
    # The corridor along: walls on both sides of the middle band, open to both corridors.
    d.box(SPINE[0] - WALL, CORRIDORS[0][1], SPINE[0], CORRIDORS[1][0], OCCUPIED)
    d.box(SPINE[1], CORRIDORS[0][1], SPINE[1] + WALL, CORRIDORS[1][0], OCCUPIED)
    d.box(SPINE[0], CORRIDORS[0][1], SPINE[1], CORRIDORS[1][0], FREE)
    for y in (CORRIDORS[0][1], CORRIDORS[1][0] - WALL):
        d.box(SPINE[0], y, SPINE[1], y + WALL, FREE)
    return d.pixels


def _door(d: Drawing, rng: np.random.Generator, x0: float, x1: float, y0: float, y1: float,
          band: int) -> None:
    """A 0.9 m door at a drawn place in the room's wall to a corridor (both walls for the
    middle band)."""
    walls = {0: (y1 - WALL,), 1: (y0, y1 - WALL), 2: (y0,)}[band]
    for wall_y in walls:
        at = float(rng.uniform(x0 + 0.3, x1 - 1.2))
        d.box(at, wall_y, at + 0.9, wall_y + WALL, FREE)


def _furniture(d: Drawing, rng: np.random.Generator, x0: float, x1: float, y0: float,
               y1: float) -> None:
    """A desk or a cabinet against a drawn wall of the room, clear of its door."""
    w, h = float(rng.uniform(0.6, 1.6)), float(rng.uniform(0.5, 0.9))
    x = float(rng.uniform(x0 + 0.4, max(x0 + 0.5, x1 - w - 0.4)))
    y = y0 + 0.6 if rng.random() < 0.5 else y1 - h - 0.6
    d.box(x, y, x + w, y + h, OCCUPIED)


def write(out_dir: Path, seed: int) -> Path:
    """Write building_SEED.yaml and .pgm into ``out_dir``; the YAML's path."""
    out_dir.mkdir(parents=True, exist_ok=True)
    pixels = building(seed)
    height, width = pixels.shape
    name = f"building_{seed}"
    (out_dir / f"{name}.pgm").write_bytes(f"P5\n{width} {height}\n255\n".encode()
                                          + pixels.tobytes())
    yaml_path = out_dir / f"{name}.yaml"
    yaml_path.write_text(f"image: {name}.pgm\nmode: trinary\nresolution: {RESOLUTION}\n"
                         f"origin: [0.0, 0.0, 0.0]\nnegate: 0\noccupied_thresh: 0.65\n"
                         f"free_thresh: 0.196\n")
    return yaml_path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("out_dir", type=Path)
    parser.add_argument("--seed", type=int, default=11)
    args = parser.parse_args()
    print(write(args.out_dir, args.seed))


if __name__ == "__main__":
    main()
