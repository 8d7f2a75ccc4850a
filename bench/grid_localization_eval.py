"""Global localization and kidnapping on the shipped maps, over seeds, without DDS.

    python bench/grid_localization_eval.py [--seeds 20] [--seconds 60]

The simulated robot (core/planar.py, as planar_robot runs it: 10 Hz, 0.5 m/s,
a seeded wandering route, odometry and scan noise) and the localizer's own
update rule (core/grid_state.py, as grid_localizer runs it: a scan after
0.25 m or 0.2 rad, 60 beams) run step by step in this process, so a 60 s run
takes a few seconds. No initial pose: the belief starts uniform over the free
cells. Per map it prints the fraction of runs whose last published pose is
within 0.3 m and 10 degrees of the truth when its scan was taken, and the localization quality
at the start and the end. Kidnapping: at half time the robot is teleported;
the lowest quality in the 10 s after, and whether the pose is found again by
the end with the scans alone (the localizer's default kidnap_probability,
1e-6, spreads that much of the belief over the map at each update).

The corridor runs with a 4 m laser: its doorways repeat every 2.2 m, so the
belief stays multi-modal until the robot sees its alcove or an end.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

BENCH = Path(__file__).resolve().parent
sys.path.insert(0, str(BENCH))
sys.path.insert(1, str(BENCH.parent))
from dataclasses import replace  # noqa: E402

from timing import table  # noqa: E402

from estimation_nodes.core.grid import likelihood_field  # noqa: E402
from estimation_nodes.core.grid import steps as grid  # noqa: E402
from estimation_nodes.core.grid.localization import GridLocalization  # noqa: E402
from estimation_nodes.core.sim import planar  # noqa: E402
from estimation_nodes.params import map_files as maps  # noqa: E402
from estimation_nodes.params.grid import default_odometry_noise, default_sensor_field  # noqa: E402

RATE_HZ = 10.0
BEAMS = 180
MAX_BEAMS = 60
RADIUS, ANGLE = 0.3, math.radians(10.0)
MAPS = {"corridor": 4.0, "office": 12.0}          # map -> laser range (m)


def run(name: str, max_range: float, seed: int, seconds: float, kidnap: bool) -> dict:
    occupancy = maps.read_map_file(BENCH.parent / "maps" / f"{name}.yaml")
    sensor = replace(default_sensor_field(), max_range=max_range)
    model = likelihood_field.grid_model(occupancy, 0.1, 72, sensor, 5_000_000)
    world = planar.planar_world(occupancy)
    noise = default_odometry_noise()
    rng = np.random.default_rng(seed)
    localization = GridLocalization(model, noise, 0.25, 0.2, 1.0, kidnap_probability=1e-6)
    pose = planar.free_place(world, rng, 0.25)
    wanderer = planar.Wanderer(rng, 0.5, 1.0, 0.25)
    odom = (0.0, 0.0, 0.0)
    angles = -math.pi + 2 * math.pi * np.arange(BEAMS) / BEAMS
    dt = 1.0 / RATE_HZ
    qualities, kidnapped_at, found_after = [], None, None
    after_kidnap = None
    steps = int(seconds * RATE_HZ)
    for step in range(steps):
        delta = wanderer.step(world, pose, dt)
        moved = planar.compose(pose, delta)
        if world.clearance_at(moved[0], moved[1]) > 0.25:
            pose = moved
        else:
            delta = (0.0, 0.0, 0.0)
        if kidnap and kidnapped_at is None and step == steps // 2:
            pose, kidnapped_at = planar.free_place(world, rng, 0.25), step
        odom = planar.compose(odom, planar.sample_odometry(delta, noise, rng))
        localization.on_odometry(odom)
        if not localization.due():
            continue
        ranges = planar.noisy_ranges(planar.ray_cast(world, pose, angles, max_range), rng,
                                     0.05, 0.05, max_range)
        valid = np.isfinite(ranges)
        chosen = np.flatnonzero(valid)
        if chosen.size > MAX_BEAMS:
            chosen = chosen[np.linspace(0, chosen.size - 1, MAX_BEAMS).round().astype(int)]
        localization.update(ranges[chosen], angles[chosen])
        estimate = localization.estimate(RADIUS, ANGLE)
        updated_at = pose            # the truth when the scan of this update was taken
        qualities.append(estimate.quality)
        if kidnapped_at is not None and found_after is None and near(estimate.pose, pose):
            found_after = (step - kidnapped_at) / RATE_HZ
        if kidnapped_at is not None:
            # The lowest quality in the 10 s after the kidnapping.
            after_kidnap = min(after_kidnap if after_kidnap is not None else 1.0,
                               estimate.quality) if step < kidnapped_at + 10 * RATE_HZ \
                else after_kidnap
    estimate = localization.estimate(RADIUS, ANGLE)
    # Against the truth of the last update: the robot moves on between updates.
    return {"found": near(estimate.pose, updated_at), "first": qualities[0], "last": qualities[-1],
            "after_kidnap": after_kidnap, "found_after": found_after,
            "updates": localization.updates}


def near(estimate, truth) -> bool:
    return (math.hypot(estimate[0] - truth[0], estimate[1] - truth[1]) <= RADIUS
            and abs(math.remainder(estimate[2] - truth[2], 2 * math.pi)) <= ANGLE)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--seconds", type=float, default=60.0)
    args = parser.parse_args()
    grid.compiled_kernels(grid.COMPILED_MIN_STATES)
    rows = []
    for name, max_range in MAPS.items():
        for kidnap in (False, True):
            started = time.perf_counter()
            results = [run(name, max_range, seed, args.seconds, kidnap)
                       for seed in range(args.seeds)]
            found = sum(r["found"] for r in results)
            first = np.median([r["first"] for r in results])
            last = np.median([r["last"] for r in results])
            row = [name, f"{max_range:g} m", "kidnapped at half time" if kidnap else "global",
                   f"{found} / {len(results)}", f"{first:.3f}", f"{last:.3f}"]
            if kidnap:
                dropped = np.median([r["after_kidnap"] for r in results])
                again = [r["found_after"] for r in results if r["found_after"] is not None]
                row += [f"{dropped:.3f}", f"{len(again)} / {len(results)}, median "
                        f"{np.median(again):.1f} s" if again else "0"]
            else:
                row += ["-", "-"]
            row.append(f"{time.perf_counter() - started:.0f} s")
            rows.append(row)
            print(f"  {name} {'kidnap' if kidnap else 'global'}: done", flush=True)
    print(f"{args.seeds} seeds, {args.seconds:g} s of wandering each, no initial pose")
    print(table(["map", "laser range", "run", "within 0.3 m and 10 deg at the end",
                 "quality at the first update (median)", "quality at the end (median)",
                 "lowest quality in the 10 s after the kidnapping (median)",
                 "found again after the kidnapping", "time"], rows))


if __name__ == "__main__":
    main()
