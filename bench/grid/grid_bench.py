"""Grid localization: one prediction and one correction on the benchmark's grid, three ways.

    python bench/grid/grid_bench.py [--repeats 5]

The office map (maps/office.yaml, 20 m x 20 m) at 0.1 m and 5 degrees: 200 x
200 x 72 = 2.88 million states; a scan of 60 beams; a motion of 0.25 m with a
small turn. Each step is timed (best and median of the repeats, one core):

- ours: the compiled kernels (core/compiled_grid.py), what the localizer runs;
- numpy's path of core/grid.py (compiled=False): vectorized over slices;
- straightforward numpy: the same model written the plain vectorized way (the
  end point cell of every state and beam gathered by fancy indexing; each
  state's mass scattered with np.add.at, then the three blurs as scipy's
  convolve1d), the reference the issue names;
- the memory-bandwidth floor: the bytes a step cannot avoid moving (the
  prediction reads and writes the tensor once per pass it needs, four; the
  correction reads the belief and writes the posterior) at the speed numpy
  copies a tensor of that size here.

Also the peak memory a step allocates (tracemalloc), against the belief tensor.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np

sys.path.insert(1, str(Path(__file__).resolve().parents[2]))  # the repository: bench
from bench.common import REPO, table  # noqa: E402

from estimation_nodes.core.grid import likelihood_field  # noqa: E402
from estimation_nodes.core.grid.laser import correct_scan  # noqa: E402
from estimation_nodes.core.grid.model import compiled_kernels  # noqa: E402
from estimation_nodes.core.grid.motion import gaussian_taps, motion_noise, predict  # noqa: E402
from estimation_nodes.params import map_files as maps  # noqa: E402
from estimation_nodes.params.grid import default_odometry_noise, default_sensor_field  # noqa: E402

DELTA = (0.1, 0.25, 0.05)


def straightforward_correct(belief, model, ranges, angles):
    """Every state's end points gathered from the field, heading by heading."""
    rows, cols = model.free.shape
    ii, jj = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
    xs, ys = model.cell_centres()
    log_likelihood = np.empty(model.shape)
    for k, heading in enumerate(model.headings()):
        x = xs[jj][..., None] + ranges * np.cos(heading + angles)
        y = ys[ii][..., None] + ranges * np.sin(heading + angles)
        col = np.floor((x - model.origin[0]) / model.resolution).astype(np.int64)
        row = np.floor((y - model.origin[1]) / model.resolution).astype(np.int64)
        inside = (row >= 0) & (row < rows) & (col >= 0) & (col < cols)
        values = np.full(row.shape, model.log_outside)
        values[inside] = model.log_field[row[inside], col[inside]]
        log_likelihood[k] = values.sum(axis=-1)
    weighted = belief * np.exp(log_likelihood - log_likelihood.max())
    return weighted / weighted.sum()


def straightforward_predict(belief, model, delta, noise):
    """Each state's mass scattered to its four bilinear targets and two heading bins with
    np.add.at, then blurred with scipy's convolve1d along each axis."""
    from scipy.ndimage import convolve1d

    rot1, trans, rot2 = delta
    bins, rows, cols = model.shape
    k, i, j = np.meshgrid(np.arange(bins), np.arange(rows), np.arange(cols), indexing="ij")
    angle = model.headings()[k] + rot1
    target_r = i + trans * np.sin(angle) / model.resolution
    target_c = j + trans * np.cos(angle) / model.resolution
    target_k = k + (rot1 + rot2) / model.bin_width
    moved = np.zeros(model.shape)
    r0, c0, k0 = np.floor(target_r), np.floor(target_c), np.floor(target_k)
    for dr in (0, 1):
        for dc in (0, 1):
            for dk in (0, 1):
                w = ((1 - abs(target_r - r0 - dr)) * (1 - abs(target_c - c0 - dc))
                     * (1 - abs(target_k - k0 - dk)))
                rr, cc = (r0 + dr).astype(np.int64), (c0 + dc).astype(np.int64)
                kk = ((k0 + dk) % bins).astype(np.int64)
                ok = (rr >= 0) & (rr < rows) & (cc >= 0) & (cc < cols) & (w > 0)
                np.add.at(moved, (kk[ok], rr[ok], cc[ok]), (belief * w)[ok])
    sigma_cells, sigma_bins = motion_noise(delta, noise, model)
    moved = convolve1d(moved, gaussian_taps(sigma_bins), axis=0, mode="wrap")
    for axis in (1, 2):
        moved = convolve1d(moved, gaussian_taps(sigma_cells), axis=axis, mode="constant")
    moved *= model.free[None]
    return moved / moved.sum()


def timed(function, repeats):
    times = []
    for _ in range(repeats):
        started = time.perf_counter()
        function()
        times.append(time.perf_counter() - started)
    return min(times), float(np.median(times))


def peak_allocation(function) -> int:
    tracemalloc.start()
    function()
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return peak


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    occupancy = maps.read_map_file(REPO / "maps" / "office.yaml")
    model = likelihood_field.grid_model(occupancy, 0.1, 72, default_sensor_field(), 5_000_000)
    rng = np.random.default_rng(0)
    belief = rng.random(model.shape) * model.free[None]
    belief /= belief.sum()
    ranges = rng.uniform(0.3, 8.0, 60)
    angles = np.linspace(-math.pi, math.pi, 60, endpoint=False)
    noise = default_odometry_noise()
    compiled_kernels(belief.size)             # compile or load before timing
    copy = timed(lambda: belief.copy(), args.repeats)[0]
    floors = {"prediction": 4 * copy, "correction": copy}
    steps = {
        "prediction": (lambda: predict(belief, model, DELTA, noise),
                       lambda: predict(belief, model, DELTA, noise, compiled=False),
                       lambda: straightforward_predict(belief, model, DELTA, noise)),
        "correction": (lambda: correct_scan(belief, model, ranges, angles),
                       lambda: correct_scan(belief, model, ranges, angles, compiled=False),
                       lambda: straightforward_correct(belief, model, ranges, angles)),
    }
    print(f"grid {model.shape[2]} x {model.shape[1]} x {model.shape[0]} = {belief.size:,} "
          f"states ({belief.nbytes / 2**20:.0f} MiB), 60 beams; best of {args.repeats} "
          f"(median in brackets); copy of the tensor {copy * 1e3:.1f} ms")
    rows = []
    for name, (ours, numpy_path, plain) in steps.items():
        ours_t, numpy_t, plain_t = (timed(f, r) for f, r in
                                    ((ours, args.repeats), (numpy_path, args.repeats),
                                     (plain, 2)))
        peak = peak_allocation(ours)
        rows.append([name, f"{ours_t[0] * 1e3:.1f} ({ours_t[1] * 1e3:.1f}) ms",
                     f"{numpy_t[0] * 1e3:.1f} ms", f"{numpy_t[0] / ours_t[0]:.1f}x",
                     f"{plain_t[0] * 1e3:.0f} ms", f"{plain_t[0] / ours_t[0]:.0f}x",
                     f"{floors[name] * 1e3:.1f} ms", f"{ours_t[0] / floors[name]:.1f}",
                     f"{peak / belief.nbytes:.1f}x"])
    ours_pred = predict(belief, model, DELTA, noise)
    plain_pred = straightforward_predict(belief, model, DELTA, noise)
    ours_post = correct_scan(belief, model, ranges, angles)[0]
    plain_post = straightforward_correct(belief, model, ranges, angles)
    print(table(["step", "ours (compiled)", "numpy's path", "numpy / ours", "straightforward "
                 "numpy", "straightforward / ours", "bandwidth floor", "ours / floor",
                 "peak allocation / belief"], rows))
    print(f"ours vs straightforward: prediction max |diff| "
          f"{np.abs(ours_pred - plain_pred).max():.2g}, correction "
          f"{np.abs(ours_post - plain_post).max():.2g}")


if __name__ == "__main__":
    main()
