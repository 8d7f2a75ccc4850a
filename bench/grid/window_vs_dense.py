"""The windowed grid filter against the dense one at full size, on a real log.

    python bench/grid/window_vs_dense.py [--log intel|aces|PATH] [--scans 40]
        [--belief-floor F ...]

The localizer of real_buildings.py (the same map, odometry, scans and prior), run
dense (belief_floor 0) and windowed (each floor given) side by side, update by
update, without the kidnap share (the dense filter spreads it over every state,
the windowed one over a lattice: two models, not one). Printed per floor: the
largest difference of any state's probability, the largest total variation
(half the L1 distance of the two beliefs), the largest difference of the
published pose and of the log evidence, and the probability the floor dropped
(all updates together). A floor far below any probability that matters
(1e-30) is the exact filter to rounding; the default (1e-9) says what it costs.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(1, str(Path(__file__).resolve().parents[2]))  # the repository: bench

from bench.common import table  # noqa: E402
from bench.grid.real_buildings import (  # noqa: E402
    LOGS,
    PRIOR_SIGMA_M,
    PRIOR_SIGMA_RAD,
    RANGE_MAX,
    beam_angles,
    building_map,
)

from estimation_nodes.core.grid.model import COMPILED_MIN_STATES, compiled_kernels  # noqa: E402
from estimation_nodes.core.grid.likelihood_field import grid_model  # noqa: E402
from estimation_nodes.params.grid import build_grid_localizer_settings  # noqa: E402
from estimation_nodes.params.specs import GRID_LOCALIZER_SPECS, spec_defaults  # noqa: E402
from estimation_nodes.tools.importers import carmen  # noqa: E402


def localizers(log, floors: list[float]):
    occupancy = building_map(log)
    values = spec_defaults(GRID_LOCALIZER_SPECS)
    values.update(max_states=200_000_000, laser_max_range=RANGE_MAX, kidnap_probability=0.0)
    settings = build_grid_localizer_settings(values)
    model = grid_model(occupancy, settings.resolution, settings.heading_bins, settings.sensor,
                       settings.max_states)
    made = []
    for floor in [0.0, *floors]:
        loc = build_grid_localizer_settings({**values, "belief_floor": floor}).localization(
            model)
        loc.set_prior(log.scans[0].pose,
                      np.diag([PRIOR_SIGMA_M ** 2] * 2 + [PRIOR_SIGMA_RAD ** 2]))
        made.append(loc)
    compiled_kernels(COMPILED_MIN_STATES)
    return settings, made


def compare(log, scans: int, floors: list[float]) -> list[list[str]]:
    settings, (dense, *windowed) = localizers(log, floors)
    worst = [{"state": 0.0, "tv": 0.0, "pose": 0.0, "evidence": 0.0, "dropped": 0.0}
             for _ in floors]
    odometry, index, updates = log.odometry, 0, 0
    for scan in log.scans[:scans]:
        stamp = int(round(scan.t * 1e9))
        while index < len(odometry) and odometry[index].t <= scan.t:
            for loc in (dense, *windowed):
                loc.on_odometry(odometry[index].pose, int(round(odometry[index].t * 1e9)))
            index += 1
        if not dense.due(stamp):
            continue
        valid = np.flatnonzero(scan.ranges < RANGE_MAX)
        if valid.size > settings.max_beams:
            valid = valid[np.linspace(0, valid.size - 1, settings.max_beams).round().astype(int)]
        ranges, angles = scan.ranges[valid], beam_angles(scan.ranges.size)[valid]
        for loc in (dense, *windowed):
            loc.update(ranges, angles, stamp)
        updates += 1
        reference = dense.estimate(settings.quality_radius, settings.quality_angle).pose
        for loc, figures in zip(windowed, worst):
            difference = np.abs(loc.belief - dense.belief)
            pose = loc.estimate(settings.quality_radius, settings.quality_angle).pose
            figures["state"] = max(figures["state"], float(difference.max()))
            figures["tv"] = max(figures["tv"], 0.5 * float(difference.sum()))
            figures["pose"] = max(figures["pose"], math.hypot(pose[0] - reference[0],
                                                              pose[1] - reference[1]))
            figures["evidence"] = max(figures["evidence"],
                                      abs(loc.log_evidence - dense.log_evidence))
            figures["dropped"] += loc.last_dropped
    return [[f"{floor:g}", str(updates), f"{f['state']:.2e}", f"{f['tv']:.2e}",
             f"{f['pose']:.2e} m", f"{f['evidence']:.2e}", f"{f['dropped']:.2e}"]
            for floor, f in zip(floors, worst)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--log", default="intel", help="intel, aces or a CARMEN log's path")
    parser.add_argument("--scans", type=int, default=40, help="scans of the log played")
    parser.add_argument("--belief-floor", type=float, action="append", default=[],
                        help="the windowed localizer's floor (default: 1e-30 and 1e-9)")
    args = parser.parse_args()
    path = LOGS.get(args.log, Path(args.log))
    if not path.exists():
        sys.exit(f"window_vs_dense: no log at {path} (see ../shared/data/README.md)")
    rows = compare(carmen.read_log(path), args.scans, args.belief_floor or [1e-30, 1e-9])
    print(f"windowed vs dense on {path.name}, every update (kidnap_probability 0)")
    print(table(["belief_floor", "updates", "max |state diff|", "max total variation",
                 "max pose diff", "max log evidence diff", "dropped (sum)"], rows))


if __name__ == "__main__":
    main()
