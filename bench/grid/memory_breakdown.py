"""Where the grid localizer's memory goes on a real building, stage by stage.

    python bench/grid/memory_breakdown.py [--log intel|aces|PATH ...] [--scans 100]

For each log, in a fresh process, the resident memory (from /proc/self/statm) and its
peak after each stage of real_buildings.py's core run: the imports, the log read, the
map made, the grid model, the localizer made and its compiled kernels loaded, the
initial pose, and some updates. Beside it: what a dense belief would take (heading bins
x rows x columns doubles) against the most the localizer's windows held
(core/grid/held.py), the share of the grid's cells that are free (the states a belief
could hold), and the share of a dense belief's memory pages that hold a free state.
The baseline: a process that imports numpy alone, and one that imports numba and
compiles one function (what the compiled kernels cost before any of ours). Issue 36
asks the node for ACES <= 400 MB and Intel <= 300 MB.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
from pathlib import Path

import numpy as np

sys.path.insert(1, str(Path(__file__).resolve().parents[2]))  # the repository: bench
from bench.common import table  # noqa: E402
from bench.grid import real_buildings as rb  # noqa: E402

PAGE = 4096
BASELINE = """
import json, resource
def mb(): return int(open('/proc/self/statm').read().split()[1]) * 4096 / 2**20
import numpy
figures = {"numpy": mb()}
import numba
figures["numba imported"] = mb()
numba.njit(lambda x: x + 1)(1)
figures["one function compiled"] = mb()
print(json.dumps(figures))
"""


def resident_mb() -> float:
    with open("/proc/self/statm", encoding="ascii") as statm:
        return int(statm.read().split()[1]) * PAGE / 2**20


def peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def free_state_pages(free: np.ndarray, heading_bins: int) -> float:
    """The share of a dense belief's pages that hold at least one free state."""
    per_layer = free.size
    first = np.flatnonzero(free.ravel())
    pages = np.unique((first[None, :] + per_layer * np.arange(heading_bins)[:, None])
                      * 8 // PAGE)
    return pages.size / -(-per_layer * heading_bins * 8 // PAGE)


def stages(log_name: str, scans: int) -> dict:
    """One log's stages in this process (run as a child: the figures are its own)."""
    figures = [("imports", resident_mb(), peak_mb())]
    log = rb.carmen.read_log(rb.resolve(log_name))
    figures.append(("log read", resident_mb(), peak_mb()))
    localization, settings = rb.localizer(log, 0.1, 72, 1e-9, True, True)
    model = localization.model
    figures.append(("map, model, localizer, kernels", resident_mb(), peak_mb()))
    localization.set_prior(log.scans[0].pose, np.diag([rb.PRIOR_SIGMA_M ** 2] * 2
                                                      + [rb.PRIOR_SIGMA_RAD ** 2]))
    figures.append(("initial pose", resident_mb(), peak_mb()))
    odometry = iter(log.odometry)
    pending = next(odometry, None)
    updates = 0
    held = localization.held_bytes
    for scan in log.scans[:scans]:
        stamp = rb.ns(scan.t)
        while pending is not None and rb.ns(pending.t) <= stamp:
            localization.on_odometry(pending.pose, rb.ns(pending.t))
            pending = next(odometry, None)
        if localization.due(stamp):
            localization.update(*rb.scan_beams(scan.ranges, settings.max_beams), stamp)
            updates += 1
        held = max(held, localization.held_bytes)
    figures.append((f"after {updates} updates", resident_mb(), peak_mb()))
    return {"figures": figures, "belief_mb": 8 * int(np.prod(model.shape)) / 2**20,
            "held_mb": held / 2**20,
            "shape": list(model.shape), "free_share": float(model.free.mean()),
            "free_pages": free_state_pages(model.free, model.heading_bins)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--log", action="append", default=[],
                        help="intel, aces or a CARMEN log's path (default: both)")
    parser.add_argument("--scans", type=int, default=100)
    parser.add_argument("--one", help=argparse.SUPPRESS)   # a child's log
    args = parser.parse_args()
    if args.one:
        print(json.dumps(stages(args.one, args.scans)))
        return
    baseline = json.loads(subprocess.run([sys.executable, "-c", BASELINE], check=True,
                                         capture_output=True, text=True).stdout)
    print("baseline: " + ", ".join(f"{k} {v:.0f} MB" for k, v in baseline.items()))
    for name in rb.chosen_logs(args.log, "memory_breakdown"):
        child = subprocess.run([sys.executable, __file__, "--one", str(name),
                                "--scans", str(args.scans)], check=True,
                               capture_output=True, text=True)
        result = json.loads(child.stdout.strip().splitlines()[-1])
        print(f"\n{name}: a dense belief {' x '.join(map(str, result['shape']))} doubles, "
              f"{result['belief_mb']:.0f} MB (the windows held: at most "
              f"{result['held_mb']:.1f} MB); free cells {100 * result['free_share']:.0f}%; "
              f"pages holding a free state {100 * result['free_pages']:.0f}%")
        print(table(["stage", "resident MB", "peak MB"],
                    [[stage, f"{now:.0f}", f"{top:.0f}"]
                     for stage, now, top in result["figures"]]))


if __name__ == "__main__":
    main()
