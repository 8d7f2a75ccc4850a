"""How well a log's corrected poses agree with the map made from them: the floor of a
localizer's score against them.

    python bench/grid/reference_fit.py [--log intel|aces|PATH ...]

The real logs' truth is their SLAM's corrected poses, and the localizer is given a
map made from those same poses (real_buildings.py). Where a corrected pose is off,
the map says so: each scan is fitted on the map near its corrected pose (the
package's scan fit, core/grid/scan_fit.py: within 0.3 m and 5 degrees, every valid
beam, on the map's 0.05 m likelihood field), and the distance from the corrected
pose to the best fit is printed. A localizer that follows the map cannot be
nearer the corrected pose than that where it is large; the map holds the scan
itself, so these figures are if anything too kind to the corrected poses.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(1, str(Path(__file__).resolve().parents[2]))  # the repository: bench
from bench.common import table  # noqa: E402
from bench.grid.real_buildings import RANGE_MAX, beam_angles, building_map, resolve  # noqa: E402

from estimation_nodes.core.grid.likelihood_field import grid_model  # noqa: E402
from estimation_nodes.core.grid.scan_fit import fitted_pose  # noqa: E402
from estimation_nodes.params.grid import build_grid_localizer_settings  # noqa: E402
from estimation_nodes.params.specs import GRID_LOCALIZER_SPECS, spec_defaults  # noqa: E402
from estimation_nodes.tools.importers import carmen  # noqa: E402

REACH_M, REACH_RAD = 0.3, math.radians(5.0)


def offsets(log_path: Path) -> tuple[np.ndarray, np.ndarray]:
    """For each scan, how far (m, rad) its best fit on the map is from its corrected pose."""
    log = carmen.read_log(log_path)
    values = spec_defaults(GRID_LOCALIZER_SPECS)
    values.update(max_states=200_000_000, laser_max_range=RANGE_MAX)
    settings = build_grid_localizer_settings(values)
    model = grid_model(building_map(log), settings.resolution, settings.heading_bins,
                       settings.sensor, settings.max_states, settings.scan_fit)
    moved, turned = [], []
    for scan in log.scans:
        valid = np.flatnonzero(scan.ranges < RANGE_MAX)
        angles = beam_angles(scan.ranges.size)
        best = fitted_pose(model.scan_fit, scan.pose, scan.ranges[valid].astype(float),
                           angles[valid], REACH_M, REACH_RAD)
        moved.append(math.hypot(best[0] - scan.pose[0], best[1] - scan.pose[1]))
        turned.append(abs(math.remainder(best[2] - scan.pose[2], 2 * math.pi)))
    return np.array(moved), np.array(turned)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--log", action="append", default=[],
                        help="intel, aces or a CARMEN log's path (default: both)")
    args = parser.parse_args()
    rows = []
    for name in args.log or ["intel", "aces"]:
        moved, turned = offsets(resolve(name))
        rows.append([name, str(moved.size), f"{100 * np.median(moved):.1f} cm",
                     f"{100 * np.percentile(moved, 95):.1f} cm", f"{np.mean(moved > 0.1):.1%}",
                     f"{np.mean(moved > 0.2):.1%}",
                     f"{np.mean(turned > math.radians(2)):.1%}"])
    print(table(["log", "scans", "best fit off the corrected pose, median", "95th percentile",
                 "> 0.1 m", "> 0.2 m", "> 2 deg"], rows))


if __name__ == "__main__":
    main()
