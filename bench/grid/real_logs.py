"""The score on real logs, side by side: our grid localizer and Nav2's AMCL, tracking and
global localization.

    python bench/grid/real_logs.py [--log intel|aces|PATH ...] [--scans N]

For each CARMEN log (../shared/data/carmen) the runs of real_buildings.py (the map from
the corrected poses, the raw odometry, the scans; the core, no DDS), twice: tracking
(the first corrected pose given, 0.3 m and 10 degrees) and global (no pose: our belief
uniform over the free cells; AMCL's particles spread over the map from its centre, the
nearest the bindings come to Nav2's global localization). The localizer runs with
grid_localizer's defaults; AMCL with Nav2's (bench/grid/amcl_baseline.py), given exactly the
scans ours took. Per run:

- converged after: the updates before the first SETTLED updates in a row all within
  0.5 m and 10 degrees of the corrected pose ("never" if none);
- from there on: the share within 0.2 m and 5 degrees and within 0.5 m and 10 degrees,
  the median and 95th percentile position and heading errors;
- confidently wrong: updates whose quality is 0.8 or more while the pose is off by more
  than 0.5 m or 30 degrees (AMCL publishes no quality: "-");
- the median time per update.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(1, str(Path(__file__).resolve().parents[2]))  # the repository: bench

from bench.common import table  # noqa: E402
from bench.grid import amcl_baseline  # noqa: E402
from bench.grid.real_buildings import amcl_child, chosen_logs, grid_child  # noqa: E402

from estimation_nodes.params.specs import GRID_LOCALIZER_SPECS, spec_defaults  # noqa: E402

WRONG_M, WRONG_RAD, SURE = 0.5, math.radians(30.0), 0.8
WIDE_M, WIDE_RAD = 0.5, math.radians(10.0)
NEAR_M, NEAR_RAD = 0.2, math.radians(5.0)
#: Updates in a row within 0.5 m and 10 degrees that make a run converged.
SETTLED = 10


def figures(result: dict) -> dict:
    """The issue's figures of one run (see the module's docstring)."""
    errors, headings = np.array(result["errors_m"]), np.array(result["headings_rad"])
    wide = (errors <= WIDE_M) & (headings <= WIDE_RAD)
    # The first update that begins SETTLED in a row within 0.5 m and 10 degrees.
    runs = np.convolve(wide.astype(int), np.ones(SETTLED, dtype=int), mode="valid")
    settled = np.flatnonzero(runs == SETTLED)
    start = int(settled[0]) if settled.size else errors.size
    after_e, after_h = errors[start:], headings[start:]
    qualities = result.get("qualities")
    wrong = "-" if qualities is None else str(int(np.sum(
        (np.array(qualities) >= SURE) & ((errors > WRONG_M) | (headings > WRONG_RAD)))))
    if after_e.size == 0:
        return {"converged": "never", "near": "-", "wide": "-", "median": "-", "p95": "-",
                "wrong": wrong}
    return {
        "converged": str(start),
        "near": f"{100 * np.mean((after_e <= NEAR_M) & (after_h <= NEAR_RAD)):.1f} %",
        "wide": f"{100 * np.mean((after_e <= WIDE_M) & (after_h <= WIDE_RAD)):.1f} %",
        "median": f"{100 * np.median(after_e):.1f} cm, "
                  f"{math.degrees(np.median(after_h)):.1f} deg",
        "p95": f"{100 * np.percentile(after_e, 95):.1f} cm, "
               f"{math.degrees(np.percentile(after_h, 95)):.1f} deg",
        "wrong": wrong}


def row(name: str, start: str, who: str, result: dict) -> list[str]:
    f = figures(result)
    return [Path(name).stem, start, who, str(result["updates"]), f["converged"], f["near"],
            f["wide"], f["median"], f["p95"], f["wrong"],
            f"{np.median(result['times_ms']):.1f}"]


HEADER = ["log", "start", "filter", "updates", "converged after", "within 0.2 m, 5 deg",
          "within 0.5 m, 10 deg", "median error", "95th percentile", "confidently wrong",
          "median ms"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--log", action="append", default=[],
                        help="intel, aces or a CARMEN log's path (default: intel and aces)")
    parser.add_argument("--scans", type=int, default=10**6,
                        help="scans of each log played (default: all)")
    parser.add_argument("--no-scan-fit", action="store_true",
                        help="scan_fit false: the pose is the belief's, not refined by the scan")
    args = parser.parse_args()
    logs = chosen_logs(args.log, "real_logs")
    if not amcl_baseline.available():
        print("real_logs: no AMCL baseline: pip install amcl==0.1.2 (the bench extra)",
              file=sys.stderr)
    floor = spec_defaults(GRID_LOCALIZER_SPECS)["belief_floor"]
    rows = []
    for name in logs:
        for start in ("tracking", "global"):
            options = argparse.Namespace(scans=args.scans, resolution=0.1, heading_bins=72,
                                         profile=False, global_start=start == "global",
                                         no_scan_fit=args.no_scan_fit)
            ours = grid_child(options, name, floor)
            rows.append(row(name, start, "grid_localizer", ours))
            if amcl_baseline.available():
                rows.append(row(name, start, "AMCL",
                                amcl_child(options, name, ours["stamps_ns"])))
            print(table(HEADER, rows), flush=True)


if __name__ == "__main__":
    main()
