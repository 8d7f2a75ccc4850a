"""Writes the maps shipped with the package (map_server format: YAML + PGM).

    python maps/generate.py

- corridor: a 16 m x 4 m corridor with six doorways evenly spaced on each side
  and one alcove near its east end: seen from inside, most places look alike,
  so the belief stays multi-modal until the robot sees the alcove.
- office: 20 m x 20 m, walls, rooms with doors, a few pillars and desks: the
  benchmark's size (2.88 million states at 0.1 m and 5 degrees).

Pixels: 254 free, 0 occupied, 205 unknown (outside the building), 0.05 m each.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
RESOLUTION = 0.05
FREE, OCCUPIED, UNKNOWN = 254, 0, 205


class Drawing:
    def __init__(self, width_m: float, height_m: float) -> None:
        self.pixels = np.full((round(height_m / RESOLUTION), round(width_m / RESOLUTION)),
                              UNKNOWN, dtype=np.uint8)

    def box(self, x0, y0, x1, y1, value) -> None:
        """Fill [x0, x1) x [y0, y1) (m, y up from the bottom edge)."""
        rows = self.pixels.shape[0]
        c0, c1 = round(x0 / RESOLUTION), round(x1 / RESOLUTION)
        r0, r1 = rows - round(y1 / RESOLUTION), rows - round(y0 / RESOLUTION)
        self.pixels[max(r0, 0):max(r1, 0), max(c0, 0):max(c1, 0)] = value

    def room(self, x0, y0, x1, y1, wall=0.1) -> None:
        self.box(x0, y0, x1, y1, OCCUPIED)
        self.box(x0 + wall, y0 + wall, x1 - wall, y1 - wall, FREE)

    def write(self, name: str, origin=(0.0, 0.0)) -> None:
        height, width = self.pixels.shape
        header = f"P5\n{width} {height}\n255\n".encode()
        (HERE / f"{name}.pgm").write_bytes(header + self.pixels.tobytes())
        (HERE / f"{name}.yaml").write_text(
            f"image: {name}.pgm\nmode: trinary\nresolution: {RESOLUTION}\n"
            f"origin: [{origin[0]}, {origin[1]}, 0.0]\nnegate: 0\n"
            f"occupied_thresh: 0.65\nfree_thresh: 0.196\n")


def corridor() -> None:
    d = Drawing(16.0, 4.0)
    d.room(0.0, 0.0, 16.0, 4.0)
    d.box(0.1, 0.1, 15.9, 0.9, OCCUPIED)        # the corridor is 2.2 m wide: y 0.9..3.1
    d.box(0.1, 3.1, 15.9, 3.9, OCCUPIED)
    for x in np.arange(1.5, 13.0, 2.2):         # doorways, the same on both sides
        d.box(x, 0.5, x + 0.9, 0.9, FREE)
        d.box(x, 3.1, x + 0.9, 3.5, FREE)
    d.box(14.2, 3.1, 15.4, 3.8, FREE)            # the alcove: one place unlike the rest
    d.write("corridor")


def office() -> None:
    d = Drawing(20.0, 20.0)
    d.room(0.0, 0.0, 20.0, 20.0)
    d.box(0.1, 9.9, 19.9, 10.1, OCCUPIED)        # a wall across, with three doors
    for x in (3.0, 9.5, 16.0):
        d.box(x, 9.9, x + 1.0, 10.1, FREE)
    d.box(6.9, 0.1, 7.1, 9.9, OCCUPIED)          # rooms below
    d.box(6.9, 4.0, 7.1, 5.0, FREE)
    d.box(13.9, 0.1, 14.1, 9.9, OCCUPIED)
    d.box(13.9, 6.0, 14.1, 7.0, FREE)
    d.box(11.9, 10.1, 12.1, 19.9, OCCUPIED)      # two halls above
    d.box(11.9, 14.0, 12.1, 15.2, FREE)
    for x, y in ((3.0, 15.0), (6.0, 15.0), (9.0, 17.5), (16.0, 16.0)):   # pillars
        d.box(x, y, x + 0.4, y + 0.4, OCCUPIED)
    d.box(1.0, 2.0, 2.6, 2.8, OCCUPIED)          # desks
    d.box(9.0, 2.0, 10.0, 4.5, OCCUPIED)
    d.box(16.5, 2.5, 18.5, 3.3, OCCUPIED)
    d.box(14.5, 12.0, 15.5, 13.0, OCCUPIED)
    d.write("office", origin=(-10.0, -10.0))


if __name__ == "__main__":
    corridor()
    office()
