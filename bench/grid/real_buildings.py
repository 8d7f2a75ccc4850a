"""The grid localizer on real buildings: time per update, memory and accuracy on real logs.

    python bench/grid/real_buildings.py [--log intel|aces|PATH ...] [--scans N]
        [--resolution 0.1] [--heading-bins 72] [--belief-floor F ...] [--profile]
        [--no-amcl] [--without-odometry-failure] [--amcl-particles N ...]

For each CARMEN log (../shared/data/carmen, see its README) a map is made from
the log's SLAM-corrected poses at 0.05 m (mapping with known poses,
core/grid/mapping.py, as estimation_map does), and the localizer of
core/grid/localization.py, with grid_localizer's defaults (60 beams, a scan
after 0.25 m or 0.2 rad, kidnap_probability, laser_independent_beams), follows
the log's raw odometry and corrects with its scans, the initial pose given
(the first corrected pose, with a 0.3 m and 10 degree spread). No DDS: the
figures are the core's, on one core (numba's kernels are single-threaded).

Per log and belief_floor it prints the map's size, its states and free states,
the time per update (prediction and correction; median, 90th percentile and
the largest; and its CPU time, the process's), the rate that makes, the peak
resident memory of a process that
ran only that configuration, and the accuracy against the corrected poses:
the fraction of updates within 0.2 m and 5 degrees, and the median errors.
belief_floor 0 is the exact filter over the whole grid; a floor > 0 drops the
states of less probability after each correction, and the steps run over the
bounding box of what is left (core/grid/localization.py says what is dropped).
Each configuration runs in a fresh process, so the memory figures are its own.
With ``--without-odometry-failure`` each floor's configuration runs again with
``odometry_failure_probability`` 0 (the model's odometry-failure component left out,
core/grid/failure.py), its row beside, and the component's cost is printed as the ratio
of the two CPU medians.

The baseline, in the same run: Nav2's AMCL (PyPI's ``amcl``, the bench extra:
amcl_baseline.py says what it binds) on the same map, given exactly the scans
the first configuration updated with and the raw odometry at each, with its
time per update and accuracy; every row's "x AMCL" is its median time over
AMCL's. Left out, with a note, where ``amcl`` is not installed. With
``--amcl-particles N ...`` AMCL runs again with N particles each (min = max), its rows
beside, and the bench prints, per log, the run of AMCL whose share within 0.2 m and 5
degrees comes nearest the first grid configuration's (of runs as near, the cheapest),
with that configuration's CPU median over that AMCL's: how our cost compares where AMCL
is as accurate as it gets.
"""

from __future__ import annotations

import argparse
import json
import math
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(1, str(Path(__file__).resolve().parents[2]))  # the repository: bench

from bench.common import SHARED_DATA, table  # noqa: E402
from bench.grid import amcl_baseline  # noqa: E402

from estimation_nodes.core.grid.model import COMPILED_MIN_STATES, compiled_kernels  # noqa: E402
from estimation_nodes.core.grid.likelihood_field import grid_model  # noqa: E402
from estimation_nodes.core.grid.mapping import MappingModel, OccupancyGridMapper  # noqa: E402
from estimation_nodes.params.grid import build_grid_localizer_settings  # noqa: E402
from estimation_nodes.params.specs import GRID_LOCALIZER_SPECS, spec_defaults  # noqa: E402
from estimation_nodes.tools.importers import carmen  # noqa: E402

DATA = SHARED_DATA / "carmen"
LOGS = {"intel": DATA / "intel-corrected.log.gz", "aces": DATA / "aces-corrected.log.gz"}
MAP_RESOLUTION = 0.05
#: Readings at or beyond this are no return in both logs (their maxima: 81.83, 50.0 m).
RANGE_MAX = 49.9
NEAR_M, NEAR_RAD = 0.2, math.radians(5.0)
PRIOR_SIGMA_M, PRIOR_SIGMA_RAD = 0.3, math.radians(10.0)


def beam_angles(count: int) -> np.ndarray:
    return -math.pi / 2 + math.pi * np.arange(count) / count


def building_map(log: carmen.CarmenLog):
    """The map a localizer is given: mapping with the log's corrected poses."""
    mapper = OccupancyGridMapper(MappingModel(MAP_RESOLUTION))
    for scan in log.scans:
        mapper.add_scan(scan.pose, scan.ranges, beam_angles(scan.ranges.size), RANGE_MAX)
    return mapper.occupancy()


def localizer(log: carmen.CarmenLog, resolution: float, heading_bins: int,
              belief_floor: float, global_start: bool = False, scan_fit: bool = True,
              **overrides):
    """The localizer with grid_localizer's defaults (and ``overrides``) on the map of
    ``log``, from its first corrected pose (or, ``global_start``, from no pose: uniform
    over the free cells), its kernels compiled; and its settings."""
    occupancy = building_map(log)
    values = spec_defaults(GRID_LOCALIZER_SPECS)
    values.update(resolution=resolution, heading_bins=heading_bins, max_states=200_000_000,
                  laser_max_range=RANGE_MAX, belief_floor=belief_floor, scan_fit=scan_fit,
                  **overrides)
    settings = build_grid_localizer_settings(values)
    model = grid_model(occupancy, resolution, heading_bins, settings.sensor,
                       settings.max_states, settings.scan_fit)
    localization = settings.localization(model)
    if not global_start:
        localization.set_prior(log.scans[0].pose,
                               np.diag([PRIOR_SIGMA_M ** 2] * 2 + [PRIOR_SIGMA_RAD ** 2]))
    compiled_kernels(COMPILED_MIN_STATES)
    return localization, settings


def scan_beams(ranges: np.ndarray, max_beams: int) -> tuple[np.ndarray, np.ndarray]:
    """The beams of a log's scan the localizer is given: ``max_beams`` evenly chosen among
    those with a return (as grid_localizer chooses them), and their angles."""
    valid = np.flatnonzero(ranges < RANGE_MAX)
    if valid.size > max_beams:
        valid = valid[np.linspace(0, valid.size - 1, max_beams).round().astype(int)]
    return ranges[valid], beam_angles(ranges.size)[valid]


def run(log_path: Path, scans: int, resolution: float, heading_bins: int,
        belief_floor: float, profile: bool, global_start: bool = False,
        scan_fit: bool = True, **overrides) -> dict:
    """The localizer on the log's first ``scans`` scans, from the first corrected pose
    (or, ``global_start``, from no pose: uniform over the free cells); ``overrides``: of
    grid_localizer's parameters."""
    log = carmen.read_log(log_path)
    localization, settings = localizer(log, resolution, heading_bins, belief_floor,
                                       global_start, scan_fit, **overrides)
    model = localization.model
    odometry = iter(log.odometry)
    pending = next(odometry, None)
    times, cpu, errors, headings, stamps, qualities = [], [], [], [], [], []
    profiler = _profiler(profile)
    for scan in log.scans[:scans]:
        stamp = ns(scan.t)
        while pending is not None and ns(pending.t) <= stamp:
            localization.on_odometry(pending.pose, ns(pending.t))
            pending = next(odometry, None)
        if not localization.due(stamp):
            continue
        ranges, angles = scan_beams(scan.ranges, settings.max_beams)
        started, started_cpu = time.perf_counter(), time.process_time()
        if profiler:
            profiler.enable()
        localization.update(ranges, angles, stamp)
        if profiler:
            profiler.disable()
        times.append(time.perf_counter() - started)
        cpu.append(time.process_time() - started_cpu)
        stamps.append(stamp)
        estimate = localization.estimate(settings.quality_radius, settings.quality_angle)
        pose = estimate.pose
        qualities.append(estimate.quality)
        errors.append(math.hypot(pose[0] - scan.pose[0], pose[1] - scan.pose[1]))
        headings.append(abs(math.remainder(pose[2] - scan.pose[2], 2 * math.pi)))
    if profiler:
        _print_profile(profiler)
    return {"cells": list(model.free.shape), "states": int(np.prod(model.shape)),
            "free_states": int(model.free.sum()) * heading_bins, "stamps_ns": stamps,
            "qualities": qualities, **_scores(times, errors, headings, cpu)}


def run_amcl(log_path: Path, stamps_ns: list[int], global_start: bool = False,
             particles: int | None = None) -> dict:
    """AMCL on the scans taken at ``stamps_ns``, each with the raw odometry pose at or
    before its time, from the same prior as the localizer; ``global_start``: from the
    map's centre with a covariance as wide as the map (the bindings cannot spread the
    particles uniformly over the free cells, as Nav2's global localization does)."""
    log = carmen.read_log(log_path)
    occupancy = building_map(log)
    if global_start:
        rows, cols = occupancy.cells.shape
        half_w, half_h = cols * occupancy.resolution / 2, rows * occupancy.resolution / 2
        prior = (occupancy.origin[0] + half_w, occupancy.origin[1] + half_h, 0.0)
        covariance = np.diag([half_w ** 2, half_h ** 2, math.pi ** 2])
    else:
        prior = log.scans[0].pose
        covariance = np.diag([PRIOR_SIGMA_M ** 2] * 2 + [PRIOR_SIGMA_RAD ** 2])
    baseline = amcl_baseline.AmclBaseline(occupancy, prior, covariance, particles)
    taken = set(stamps_ns)
    odometry, index = log.odometry, 0
    times, cpu, errors, headings = [], [], [], []
    for scan in log.scans:
        if ns(scan.t) not in taken:
            continue
        while index + 1 < len(odometry) and odometry[index + 1].t <= scan.t:
            index += 1
        started, started_cpu = time.perf_counter(), time.process_time()
        pose = baseline.update(scan.ranges, beam_angles(scan.ranges.size), RANGE_MAX,
                               odometry[index].pose)
        times.append(time.perf_counter() - started)
        cpu.append(time.process_time() - started_cpu)
        errors.append(math.hypot(pose[0] - scan.pose[0], pose[1] - scan.pose[1]))
        headings.append(abs(math.remainder(pose[2] - scan.pose[2], 2 * math.pi)))
    return {"cells": list(occupancy.cells.shape), "qualities": None,
            **_scores(times, errors, headings, cpu)}


def _scores(times: list[float], errors: list[float], headings: list[float],
            cpu: list[float]) -> dict:
    errors_a, headings_a = np.array(errors), np.array(headings)
    return {"updates": len(times), "times_ms": [1e3 * t for t in times],
            "cpu_ms": [1e3 * t for t in cpu],
            "errors_m": errors, "headings_rad": headings,
            "near": float(np.mean((errors_a <= NEAR_M) & (headings_a <= NEAR_RAD))),
            "median_error_m": float(np.median(errors_a)),
            "median_error_deg": math.degrees(float(np.median(headings_a))),
            "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}


def ns(t: float) -> int:
    """A log's time (s) as a stamp (ns)."""
    return int(round(t * 1e9))


def _profiler(profile: bool):
    if not profile:
        return None
    import cProfile
    return cProfile.Profile()


def _print_profile(profiler) -> None:
    import pstats
    pstats.Stats(profiler, stream=sys.stderr).sort_stats("cumulative").print_stats(18)


def resolve(name: str) -> Path:
    return LOGS.get(name, Path(name))


def chosen_logs(names: list[str], script: str) -> list[str]:
    """The logs a script was given (default: intel and aces); it exits, saying where it
    looked, when one is not there."""
    logs = names or ["intel", "aces"]
    missing = [name for name in logs if not resolve(name).exists()]
    if missing:
        sys.exit(f"{script}: no log at {', '.join(str(resolve(n)) for n in missing)} "
                 f"(see ../shared/data/README.md)")
    return logs


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--log", action="append", default=[],
                        help="intel, aces or a CARMEN log's path (default: intel and aces)")
    parser.add_argument("--scans", type=int, default=200, help="scans of each log played")
    parser.add_argument("--resolution", type=float, default=0.1)
    parser.add_argument("--heading-bins", type=int, default=72)
    parser.add_argument("--belief-floor", type=float, action="append", default=[],
                        help="the localizer's belief_floor (default: 0 and its default)")
    parser.add_argument("--profile", action="store_true", help="cProfile of the updates")
    parser.add_argument("--no-amcl", action="store_true", help="leave the AMCL baseline out")
    parser.add_argument("--without-odometry-failure", action="store_true",
                        help="each floor also with odometry_failure_probability 0, and the "
                             "component's cost as the ratio of the CPU medians")
    parser.add_argument("--odometry-failure-probability", type=float,
                        help=argparse.SUPPRESS)   # a child's run of it
    parser.add_argument("--amcl-particles", type=int, nargs="+", default=[],
                        help="AMCL also with these particle counts, and our cost against "
                             "the one nearest our accuracy")
    parser.add_argument("--particles", type=int, help=argparse.SUPPRESS)   # an AMCL child's
    parser.add_argument("--one", help=argparse.SUPPRESS)   # a child's run, as JSON
    parser.add_argument("--stamps", help=argparse.SUPPRESS)   # the AMCL child's scans
    parser.add_argument("--global-start", action="store_true",
                        help="no initial pose: global localization from a uniform belief")
    parser.add_argument("--no-scan-fit", action="store_true",
                        help="scan_fit false: the pose is the belief's, not refined by the scan")
    args = parser.parse_args()
    if args.one:
        print(json.dumps(run_one(args)))
        return
    logs = chosen_logs(args.log, "real_buildings")
    floors = args.belief_floor or [0.0, spec_defaults(GRID_LOCALIZER_SPECS)["belief_floor"]]
    with_amcl = not args.no_amcl and amcl_baseline.available()
    if not args.no_amcl and not with_amcl:
        print("real_buildings: no AMCL baseline: pip install amcl==0.1.2 (the bench extra)",
              file=sys.stderr)
    rows, costs = [], []
    for name in logs:
        results = []
        for floor in floors:
            results.append((f"grid, floor {floor:g}", grid_child(args, name, floor)))
            if args.without_odometry_failure:
                results.append((f"grid, floor {floor:g}, odometry failure left out",
                                grid_child(args, name, floor, odometry_failure=0.0)))
                costs.append(_component_cost(name, floor, results[-2][1], results[-1][1]))
        amcl = None
        if with_amcl:
            stamps = results[0][1]["stamps_ns"]
            amcl = amcl_child(args, name, stamps)
            swept = [(count, amcl_child(args, name, stamps, count))
                     for count in args.amcl_particles]
            results += [("AMCL", amcl)] + [(f"AMCL, {count} particles", result)
                                           for count, result in swept]
            if swept:
                costs.append(_nearest_amcl(name, results[0], [(None, amcl)] + swept))
        rows += [_row(name, label, result, amcl) for label, result in results]
        print(table(HEADER, rows), flush=True)
    for line in costs:
        print(line)


def _nearest_amcl(name: str, ours: tuple[str, dict], runs: list[tuple[int | None, dict]]) -> str:
    """The AMCL run whose accuracy comes nearest ours (of those as near, the cheapest: the
    comparison least kind to us), and our CPU median over its."""
    label, result = ours
    count, nearest = min(runs, key=lambda run: (round(abs(run[1]["near"] - result["near"]), 6),
                                                np.median(run[1]["cpu_ms"])))
    ratio = np.median(result["cpu_ms"]) / np.median(nearest["cpu_ms"])
    particles = "Nav2's 500 to 2000" if count is None else str(count)
    return (f"{Path(name).stem}: AMCL nearest our accuracy ({100 * result['near']:.1f} % "
            f"within 0.2 m, 5 deg): {particles} particles, {100 * nearest['near']:.1f} %; "
            f"{label} / that AMCL, CPU median: {ratio:.2f}")


def _component_cost(name: str, floor: float, with_it: dict, without: dict) -> str:
    ratio = np.median(with_it["cpu_ms"]) / np.median(without["cpu_ms"])
    return (f"{Path(name).stem}, floor {floor:g}: the odometry-failure component costs "
            f"{100 * (ratio - 1):+.1f} % CPU per update (median {np.median(with_it['cpu_ms']):.1f}"
            f" ms with it, {np.median(without['cpu_ms']):.1f} ms without)")


def run_one(args: argparse.Namespace) -> dict:
    """A child's run (``--one LOG,FLOOR`` or ``--one LOG,amcl``)."""
    log, floor = args.one.split(",")
    if floor == "amcl":
        stamps = json.loads(Path(args.stamps).read_text())
        return run_amcl(resolve(log), stamps, args.global_start, args.particles)
    overrides = {} if args.odometry_failure_probability is None else \
        {"odometry_failure_probability": args.odometry_failure_probability}
    return run(resolve(log), args.scans, args.resolution, args.heading_bins, float(floor),
               args.profile, args.global_start, not args.no_scan_fit, **overrides)


HEADER = ["log", "filter", "cells", "states", "free states", "updates",
          "median ms", "p90 ms", "max ms", "Hz (median)", "x AMCL", "CPU median ms",
          "x AMCL (CPU)", "peak RSS MB", "within 0.2 m, 5 deg", "median error"]


def grid_child(args: argparse.Namespace, name: str, floor: float,
               odometry_failure: float | None = None) -> dict:
    command = [sys.executable, __file__, "--one", f"{name},{floor!r}", "--scans",
               str(args.scans), "--resolution", str(args.resolution), "--heading-bins",
               str(args.heading_bins)] + (["--profile"] if args.profile else []) \
        + (["--global-start"] if getattr(args, "global_start", False) else []) \
        + (["--no-scan-fit"] if getattr(args, "no_scan_fit", False) else []) \
        + ([] if odometry_failure is None
           else ["--odometry-failure-probability", repr(odometry_failure)])
    done = subprocess.run(command, stdout=subprocess.PIPE, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def amcl_child(args: argparse.Namespace, name: str, stamps_ns: list[int],
               particles: int | None = None) -> dict:
    with tempfile.NamedTemporaryFile("w", suffix=".json") as stamps:
        json.dump(stamps_ns, stamps)
        stamps.flush()
        command = [sys.executable, __file__, "--one", f"{name},amcl", "--stamps", stamps.name] \
            + (["--global-start"] if getattr(args, "global_start", False) else []) \
            + ([] if particles is None else ["--particles", str(particles)])
        done = subprocess.run(command, stdout=subprocess.PIPE, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def _row(name: str, label: str, result: dict, amcl: dict | None) -> list[str]:
    """One table row; "x AMCL" is the median wall time over AMCL's, "x AMCL (CPU)" the
    median CPU time (the process's) over AMCL's: on a busy machine the wall times of the
    two, measured one after the other, meet other loads, their CPU times much less."""
    times, cpu = np.array(result["times_ms"]), np.array(result["cpu_ms"])
    rows, cols = result["cells"]
    states = f"{result['states'] / 1e6:.2f} M" if "states" in result else "-"
    free = f"{result['free_states'] / 1e6:.2f} M" if "free_states" in result else "-"
    ratio = f"{np.median(times) / np.median(amcl['times_ms']):.2f}" if amcl else "-"
    cpu_ratio = f"{np.median(cpu) / np.median(amcl['cpu_ms']):.2f}" if amcl else "-"
    return [Path(name).stem, label, f"{cols} x {rows}", states, free, str(result["updates"]),
            f"{np.median(times):.1f}", f"{np.percentile(times, 90):.1f}", f"{times.max():.1f}",
            f"{1e3 / np.median(times):.1f}", ratio, f"{np.median(cpu):.1f}", cpu_ratio,
            f"{result['peak_rss_mb']:.0f}", f"{100 * result['near']:.1f} %",
            f"{100 * result['median_error_m']:.1f} cm, {result['median_error_deg']:.1f} deg"]


if __name__ == "__main__":
    main()
