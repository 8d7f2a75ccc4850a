"""Global localization and kidnapping, over seeds, without DDS; how often the localizer is
confidently wrong.

    python bench/grid/grid_localization_eval.py [--seeds 20] [--seconds 60]
    python bench/grid/grid_localization_eval.py --map MAP.yaml [--map ...] [--building SEED ...]
        [--laser-range 12] [--resolution 0.1] [--heading-bins 72] [--runs global]
        [--independent-beams K ...]

The simulated robot (core/sim/planar.py, as planar_robot runs it with its
defaults: 10 Hz, 0.5 m/s, a seeded wandering route, odometry and scan noise)
and the localizer (core/grid/localization.py with grid_localizer's defaults
from the spec table: a scan after 0.25 m or 0.2 rad, 60 beams) run step by
step in this process, so a 60 s run takes seconds. No initial pose: the
belief starts uniform over the free cells. Per map and run it prints the
fraction of runs whose last pose is within 0.3 m and 10 degrees of the truth
when its scan was taken, the localization quality at the first update and
at the end, and how many updates were confidently wrong: a quality of at
least 0.8 for a pose more than 0.5 m or 30 degrees from the truth of its
scan (in global runs: after a kidnapping the belief is rightly sure of the old
place until the scans disagree). Kidnapping: at half time the robot is
teleported; the lowest quality in the 10 s after, and whether the pose is
found again by the end with the scans alone (kidnap_probability).

By default the shipped maps: the corridor with a 4 m laser (its doorways
repeat every 2.2 m, so the belief stays multi-modal until the robot sees its
alcove or an end) and the office with a 12 m one. ``--map`` takes any
map_server map instead and ``--building SEED`` a building drawn from a seed
(bench/grid/building_map.py): maps no parameter was tuned on. ``--independent-beams``
runs the localizer with that ``laser_independent_beams`` instead of its default,
a row for each value given.
"""

from __future__ import annotations

import argparse
import itertools
import math
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

sys.path.insert(1, str(Path(__file__).resolve().parents[2]))  # the repository: bench

from bench.common import REPO, table  # noqa: E402
from bench.grid import building_map  # noqa: E402

from estimation_nodes.core.grid.model import COMPILED_MIN_STATES, compiled_kernels  # noqa: E402
from estimation_nodes.core.sim import planar  # noqa: E402
from estimation_nodes.params.grid import (  # noqa: E402
    build_grid_localizer_settings,
    build_planar_robot_settings,
)
from estimation_nodes.params.specs import (  # noqa: E402
    GRID_LOCALIZER_SPECS,
    PLANAR_ROBOT_SPECS,
    spec_defaults,
)

RADIUS, ANGLE = 0.3, math.radians(10.0)
#: Confidently wrong: at least this quality for a pose farther than this from the truth.
CONFIDENT, WRONG_M, WRONG_RAD = 0.8, 0.5, math.radians(30.0)
SHIPPED = REPO / "maps"


@dataclass(frozen=True)
class MapRun:
    """A map and the localizer's grid on it."""

    name: str
    path: Path
    laser_range: float
    resolution: float
    heading_bins: int


def run(case: MapRun, seed: int, seconds: float, kidnap: bool,
        independent_beams: int | None = None, belief_floor: float | None = None) -> dict:
    values = spec_defaults(GRID_LOCALIZER_SPECS)
    # max_states as large as a real building needs (the node's default stops at 5 M).
    values.update(map_file=str(case.path), laser_max_range=case.laser_range,
                  resolution=case.resolution, heading_bins=case.heading_bins,
                  max_states=200_000_000)
    if belief_floor is not None:
        values.update(belief_floor=belief_floor)
    if independent_beams is not None:
        values.update(laser_independent_beams=independent_beams)
    settings = build_grid_localizer_settings(values)
    robot_values = spec_defaults(PLANAR_ROBOT_SPECS)
    robot_values.update(map_file=str(case.path), laser_max_range=case.laser_range)
    robot = build_planar_robot_settings(robot_values)
    localization = settings.localization(settings.model)
    world = planar.planar_world(robot.map)
    rng = np.random.default_rng(seed)
    pose = planar.free_place(world, rng, robot.robot_radius)
    wanderer = planar.Wanderer(rng, robot.speed, robot.turn_rate, robot.robot_radius)
    odom = (0.0, 0.0, 0.0)
    angles = -math.pi + 2 * math.pi * np.arange(robot.beams) / robot.beams
    dt = 1.0 / robot.rate_hz
    qualities, kidnapped_at, found_after = [], None, None
    after_kidnap = None
    confidently_wrong = confident = 0
    steps = int(seconds * robot.rate_hz)
    for step in range(steps):
        delta = wanderer.step(world, pose, dt)
        moved = planar.compose(pose, delta)
        if world.clearance_at(moved[0], moved[1]) > robot.robot_radius:
            pose = moved
        else:
            delta = (0.0, 0.0, 0.0)
        if kidnap and kidnapped_at is None and step == steps // 2:
            pose, kidnapped_at = planar.free_place(world, rng, robot.robot_radius), step
        odom = planar.compose(odom, planar.sample_odometry(delta, robot.noise, rng))
        localization.on_odometry(odom)
        if not localization.due():
            continue
        ranges = planar.noisy_ranges(planar.ray_cast(world, pose, angles, case.laser_range),
                                     rng, robot.scan_noise_std, robot.scan_random_fraction,
                                     case.laser_range)
        chosen = np.flatnonzero(np.isfinite(ranges))
        if chosen.size > settings.max_beams:
            chosen = chosen[np.linspace(0, chosen.size - 1,
                                        settings.max_beams).round().astype(int)]
        localization.update(ranges[chosen], angles[chosen])
        estimate = localization.estimate(settings.quality_radius, settings.quality_angle)
        updated_at = pose            # the truth when the scan of this update was taken
        qualities.append(estimate.quality)
        if estimate.quality >= CONFIDENT:
            confident += 1
            confidently_wrong += not near(estimate.pose, pose, WRONG_M, WRONG_RAD)
        if kidnapped_at is not None and found_after is None and near(estimate.pose, pose):
            found_after = (step - kidnapped_at) * dt
        if kidnapped_at is not None:
            # The lowest quality in the 10 s after the kidnapping.
            after_kidnap = min(after_kidnap if after_kidnap is not None else 1.0,
                               estimate.quality) if step < kidnapped_at + 10 / dt \
                else after_kidnap
    estimate = localization.estimate(settings.quality_radius, settings.quality_angle)
    # Against the truth of the last update: the robot moves on between updates.
    return {"found": near(estimate.pose, updated_at), "first": qualities[0], "last": qualities[-1],
            "after_kidnap": after_kidnap, "found_after": found_after,
            "updates": localization.updates, "confidently_wrong": confidently_wrong,
            "confident": confident}


def near(estimate, truth, radius: float = RADIUS, angle: float = ANGLE) -> bool:
    return (math.hypot(estimate[0] - truth[0], estimate[1] - truth[1]) <= radius
            and abs(math.remainder(estimate[2] - truth[2], 2 * math.pi)) <= angle)


def map_runs(args: argparse.Namespace, scratch: Path) -> list[MapRun]:
    given = [MapRun(path.stem, path, args.laser_range, args.resolution, args.heading_bins)
             for path in args.map]
    given += [MapRun(f"building {seed}", building_map.write(scratch, seed), args.laser_range,
                     args.resolution, args.heading_bins) for seed in args.building]
    if given:
        return given
    return [MapRun("corridor", SHIPPED / "corridor.yaml", 4.0, 0.1, 72),
            MapRun("office", SHIPPED / "office.yaml", 12.0, 0.1, 72)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--map", type=Path, action="append", default=[],
                        help="a map_server map to run on instead of the shipped ones")
    parser.add_argument("--building", type=int, action="append", default=[],
                        help="a building drawn from this seed (bench/grid/building_map.py)")
    parser.add_argument("--laser-range", type=float, default=12.0, help="for --map, --building")
    parser.add_argument("--resolution", type=float, default=0.1, help="for --map, --building")
    parser.add_argument("--heading-bins", type=int, default=72, help="for --map, --building")
    parser.add_argument("--belief-floor", type=float, default=None,
                        help="the localizer's belief_floor instead of its default")
    parser.add_argument("--runs", default="global,kidnap",
                        help="global, kidnap or both (comma-separated)")
    parser.add_argument("--independent-beams", type=int, action="append", default=[],
                        help="the localizer's laser_independent_beams instead of its default; "
                             "several: a row for each")
    args = parser.parse_args()
    kinds = [kind == "kidnap" for kind in args.runs.split(",")]
    compiled_kernels(COMPILED_MIN_STATES)
    rows = []
    default_beams = spec_defaults(GRID_LOCALIZER_SPECS)["laser_independent_beams"]
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    with tempfile.TemporaryDirectory() as scratch:
        for case, kidnap, beams in itertools.product(map_runs(args, Path(scratch)), kinds,
                                                      args.independent_beams or [None]):
            started = time.perf_counter()
            results = [run(case, seed, args.seconds, kidnap, beams, args.belief_floor)
                       for seed in seeds]
            found = sum(r["found"] for r in results)
            first = np.median([r["first"] for r in results])
            last = np.median([r["last"] for r in results])
            wrong = sum(r["confidently_wrong"] for r in results)
            confident = sum(r["confident"] for r in results)
            updates = sum(r["updates"] for r in results)
            row = [case.name, f"{case.laser_range:g} m", str(beams or default_beams),
                   "kidnapped at half time" if kidnap else "global",
                   f"{found} / {len(results)}", f"{first:.3f}", f"{last:.3f}",
                   f"{confident} / {updates}"]
            # After a kidnapping the belief is rightly sure of the old place until the
            # scans disagree: confidently wrong counts in global runs only.
            row += ["-", "-"] if kidnap else [
                f"{wrong} / {updates}",
                f"{sum(r['confidently_wrong'] > 0 for r in results)} / {len(results)}"]
            if kidnap:
                dropped = np.median([r["after_kidnap"] for r in results])
                again = [r["found_after"] for r in results if r["found_after"] is not None]
                row += [f"{dropped:.3f}", f"{len(again)} / {len(results)}, median "
                        f"{np.median(again):.1f} s" if again else "0"]
            else:
                row += ["-", "-"]
            row.append(f"{time.perf_counter() - started:.0f} s")
            rows.append(row)
            print(f"  done: {' | '.join(str(cell) for cell in row)}", flush=True)
    print(f"seeds {seeds.start}..{seeds.stop - 1}, {args.seconds:g} s of wandering each, no "
          f"initial pose")
    print(table(["map", "laser range", "independent beams", "run",
                 "within 0.3 m and 10 deg at the end",
                 "quality at the first update (median)", "quality at the end (median)",
                 "updates with quality >= 0.8",
                 "confidently wrong updates (quality >= 0.8, off > 0.5 m or 30 deg)",
                 "runs with one", "lowest quality in the 10 s after the kidnapping (median)",
                 "found again after the kidnapping", "time"], rows))


if __name__ == "__main__":
    main()
