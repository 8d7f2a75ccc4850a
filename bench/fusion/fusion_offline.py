"""robot_localization's bags through estimation_fuse: seconds per run and times real time.

    python bench/fusion/fusion_offline.py [--repeats N] [--quick]

For each of the peer's bag tests (test1.bag, the Husky's 395 s; test2.bag, the Jackal's
61 s; ../shared/data/robot_localization) and each filter (ekf, ukf), with the peer's
parameter files (tests/data/robot_localization/) and, for test1, the IMU's mount:
- ``estimation_fuse`` as a process, as a user runs it: start, imports, numba's kernels
  loaded from its cache, the bag read and filtered, the final pose printed;
- the same run in-process (offline.run on the bag's messages, kernels already loaded);
- the reference, measured in the same repeats: reading and decoding the bag's messages
  alone, in-process (what any run of the bag costs before the filter).
Repeats are interleaved, so a busy machine slows all alike; the table gives the best
and the median of each. Nothing is asserted: these are measurements.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(1, str(Path(__file__).resolve().parents[2]))  # the repository: bench
from bench.common import REPO, SHARED_DATA, table  # noqa: E402

from estimation_nodes.core.fusion import steps  # noqa: E402
from estimation_nodes.params.fusion import fusion_config, parameters_of_file  # noqa: E402
from estimation_nodes.tools.fusion import offline  # noqa: E402

SHARED = SHARED_DATA / "robot_localization"
FILES = REPO / "tests" / "data" / "robot_localization"
#: test1.bag has no /tf: the IMU's mount as the peer's test publishes it (test_fusion_bags.py).
HUSKY_IMU_MOUNT = "imu_link=0,-0.3,0.52,1.570796327,0,-1.570796327"
BAGS = {"test1.bag": "1", "test2.bag": "2"}


class Case:
    """One bag with one filter: its command line and its in-process run."""

    def __init__(self, bag: str, kind: str) -> None:
        self.bag, self.kind = bag, kind
        self.params = FILES / f"test_{kind}_localization_node_bag{BAGS[bag]}.yaml"
        self.mount = [HUSKY_IMU_MOUNT] if bag == "test1.bag" else []
        self.config = fusion_config(parameters_of_file(str(self.params)))
        self.topics = {sensor.topic for sensor in self.config.sensors.values()}

    @property
    def command(self) -> list[str]:
        mounts = [arg for mount in self.mount for arg in ("--mount", mount)]
        return [sys.executable, "-m", "estimation_nodes.tools.fusion.offline",
                str(SHARED / self.bag), "--params-file", str(self.params), *mounts]

    def messages(self) -> list:
        return list(offline.bag_messages(SHARED / self.bag, self.topics))

    def span_s(self) -> float:
        stamps = [stamp for stamp, _, _ in self.messages()]
        return (stamps[-1] - stamps[0]) * 1e-9

    def run_in_process(self) -> offline.FusionRun:
        mounts = dict(offline.parse_mount(mount) for mount in self.mount)
        return offline.run(self.config, offline.bag_messages(SHARED / self.bag, self.topics),
                           mounts)


def seconds(action) -> float:
    start = time.perf_counter()
    action()
    return time.perf_counter() - start


def process(case: Case) -> None:
    result = subprocess.run(case.command, capture_output=True, text=True, timeout=600)
    if result.returncode != 0:
        raise RuntimeError(f"{' '.join(case.command)} failed:\n{result.stderr}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeats", type=int, default=3, help="interleaved repeats (3)")
    parser.add_argument("--quick", action="store_true", help="test2.bag only, one repeat")
    args = parser.parse_args()
    if not SHARED.is_dir():
        print(f"{SHARED} is absent: nothing to measure")
        return 0
    bags = ["test2.bag"] if args.quick else list(BAGS)
    repeats = 1 if args.quick else args.repeats
    cases = [Case(bag, kind) for bag in bags for kind in ("ekf", "ukf")]
    spans = {case.bag: case.span_s() for case in cases}
    # Compiled (or loaded from numba's cache) before anything is timed, as for a user's
    # second run: the first one after an install compiles them once.
    steps.prepare_compiled()
    process(cases[0])
    times: dict[tuple[str, str, str], list[float]] = {}
    loads = []
    for _ in range(repeats):
        loads.append(os.getloadavg()[0])
        for case in cases:
            for what, action in (("process", lambda case=case: process(case)),
                                 ("in-process", case.run_in_process),
                                 ("read", case.messages)):
                times.setdefault((case.bag, case.kind, what), []).append(seconds(action))
    rows = []
    for case in cases:
        span = spans[case.bag]
        best = {what: min(times[(case.bag, case.kind, what)])
                for what in ("process", "in-process", "read")}
        median = {what: statistics.median(times[(case.bag, case.kind, what)])
                  for what in ("process", "in-process", "read")}
        rows.append([case.bag, f"{span:.1f} s", case.kind,
                     f"{best['process']:.2f} s ({median['process']:.2f})",
                     f"{span / best['process']:.0f}x",
                     f"{best['in-process']:.2f} s ({median['in-process']:.2f})",
                     f"{span / best['in-process']:.0f}x",
                     f"{best['read']:.2f} s", f"{best['in-process'] / best['read']:.1f}"])
    print(f"estimation_fuse on robot_localization's bags: best of {repeats} interleaved "
          f"repeats (median); load average {min(loads):.1f}..{max(loads):.1f} on "
          f"{os.cpu_count()} cores")
    print(table(["bag", "span", "filter", "process", "x real time", "in-process",
                 "x real time", "read only", "in-process / read"], rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
