"""The landmark filter's figures for the UTIAS robots, derived from their data.

Every noise figure and calibration of the UTIAS parameter file
(msgs_config/robots/utias_mrclam.yaml) comes from this script, pooled over the robots
given (by default 1 to 3 of dataset 7): one set of figures for every robot, none
tuned to one. The ground truth (Vicon) is what each figure is measured against:

- the camera: where it sees from on the robot, relative to the point Vicon tracks
  (sensor_pose, fitted by least squares with the range's scale: an offset of a few
  centimetres is a bias the filter would otherwise carry into every pose), its
  reported range against the true distance and against the true depth (the distance
  along the camera's axis), the scale of the better one, the spread of what is left
  (std = a + b * range), and the bearing's std; each robot's own scale and mount,
  whose spread (range_scale_std, sensor_pose_std) is how well the pooled ones fit a
  robot the figures never saw;
- the odometry (commanded speeds): the delay after which the robot follows a
  command, the share of the commanded forward and turn speeds it drives, and the
  variance of a step's distance and turn (the filter's noise.* terms), fitted over
  windows of WINDOW_S seconds.

    python bench/landmarks/utias_calibration.py [--dataset DIR] [--robots 1 2 3]

bench/landmarks/ekf_real.py --cross-validate calls ``calibrate`` with each robot left out.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares, nnls

sys.path.insert(1, str(Path(__file__).resolve().parents[2]))  # the repository: bench
from bench.common import SHARED_DATA  # noqa: E402

from estimation_nodes.tools.importers.utias import UtiasRun, read_run  # noqa: E402

DATASET = SHARED_DATA / "utias" / "MRCLAM_Dataset7"
#: Seconds over which the odometry's errors are fitted: the order of the time a
#: robot goes without seeing a landmark, where the filter lives on odometry alone.
WINDOW_S = 5.0
#: Delays (s) tried between a command's stamp and the robot following it.
DELAYS = np.round(np.arange(0.0, 0.51, 0.05), 2)
#: An observation this far from the truth (rad of bearing) is a misidentification,
#: left out of the camera's figures (the filter's gate is for those).
OUTLIER_BEARING = 0.1
#: The range std's constant term is at least this (m): the fit finds the spread
#: proportional to the range, and the filter needs a term > 0.
MIN_RANGE_STD = 0.001


def _wrap(angle: np.ndarray) -> np.ndarray:
    return (angle + np.pi) % (2 * np.pi) - np.pi


def _truth_at(run: UtiasRun, times: np.ndarray) -> np.ndarray:
    """Vicon's x, y, unwrapped heading at ``times`` (linear interpolation)."""
    truth = run.truth
    heading = np.unwrap(truth[:, 3])
    return np.column_stack([np.interp(times, truth[:, 0], truth[:, i]) for i in (1, 2)]
                           + [np.interp(times, truth[:, 0], heading)])


def _camera_poses(poses: np.ndarray, mount: Sequence[float]) -> np.ndarray:
    """The camera's x, y, heading for robot ``poses`` with the camera at ``mount``
    (x, y, yaw on the robot; sensor_pose's convention)."""
    x, y, yaw = mount
    cos, sin = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    return np.column_stack([poses[:, 0] + cos * x - sin * y, poses[:, 1] + sin * x + cos * y,
                            poses[:, 2] + yaw])


def landmark_geometry(run: UtiasRun, mount: Sequence[float] = (0.0, 0.0, 0.0)
                      ) -> dict[str, np.ndarray]:
    """For every detection of a landmark: the reported range and bearing, the true
    distance, depth and bearing from the camera, at ``mount`` on Vicon's pose of the
    robot at the detection's time."""
    detections = run.detections
    known = np.array([int(s) in run.landmarks for s in detections[:, 1]], dtype=bool)
    detections = detections[known]
    where = np.array([run.landmarks[int(s)] for s in detections[:, 1]])
    pose = _camera_poses(_truth_at(run, detections[:, 0]), mount)
    dx, dy = where[:, 0] - pose[:, 0], where[:, 1] - pose[:, 1]
    cos, sin = np.cos(pose[:, 2]), np.sin(pose[:, 2])
    return {"range": detections[:, 2], "bearing": detections[:, 3],
            "distance": np.hypot(dx, dy), "depth": dx * cos + dy * sin,
            "true_bearing": _wrap(np.arctan2(dy, dx) - pose[:, 2])}


def _pooled_geometry(runs: Sequence[UtiasRun], mount: Sequence[float]
                     ) -> dict[str, np.ndarray]:
    pooled = [landmark_geometry(run, mount) for run in runs]
    return {key: np.concatenate([g[key] for g in pooled]) for key in pooled[0]}


def _fit_mount(runs: Sequence[UtiasRun], kind: str, keep: np.ndarray,
               spreads: tuple[float, float]) -> tuple[float, np.ndarray, float]:
    """The range's scale and the camera's mount (x, y, yaw) that fit the detections
    ``keep`` best (least squares of the range's residual relative to the range and of
    the bearing's, each over its ``spreads``), and the range residual's rms there."""
    relative_std, bearing_std = spreads

    def residuals(q: np.ndarray) -> np.ndarray:
        seen = _pooled_geometry(runs, q[1:])
        measured = seen["range"][keep]
        return np.concatenate([
            (measured - q[0] * seen[kind][keep]) / measured / relative_std,
            _wrap(seen["bearing"] - seen["true_bearing"])[keep] / bearing_std])

    fit = least_squares(residuals, np.array([1.0, 0.0, 0.0, 0.0]), x_scale=0.01)
    seen = _pooled_geometry(runs, fit.x[1:])
    misfit = _rms(seen["range"][keep] - fit.x[0] * seen[kind][keep])
    return float(fit.x[0]), fit.x[1:], misfit


def camera_figures(runs: Sequence[UtiasRun]) -> dict[str, object]:
    """The range model that fits best, its scale, the camera's mount on the robot (where
    it is seen from, relative to the point Vicon tracks), the range's and the bearing's
    spread there."""
    seen = _pooled_geometry(runs, (0.0, 0.0, 0.0))
    bearing_error = _wrap(seen["bearing"] - seen["true_bearing"])
    keep = np.abs(bearing_error) < OUTLIER_BEARING
    figures: dict[str, object] = {"observations": float(keep.sum()),
                                  "outliers": float((~keep).sum())}
    # the spreads that weigh range against bearing in the mount's fit: the residuals
    # with the camera at Vicon's point, the range's relative to the range
    relative = (seen["range"] - seen["distance"]) / seen["range"]
    spreads = (_rms(relative[keep] - relative[keep].mean()), _rms(bearing_error[keep]))
    fits = {kind: _fit_mount(runs, kind, keep, spreads) for kind in ("distance", "depth")}
    for kind, (scale, _, misfit) in fits.items():
        # root mean square, not std: a bias is an error the filter cannot model either
        figures[f"{kind}_scale"] = scale
        figures[f"{kind}_residual_std"] = misfit
    kind = min(fits, key=lambda name: fits[name][2])
    scale, mount, _ = fits[kind]
    figures["range_model"] = "depth" if kind == "depth" else "euclidean"
    figures["range_scale"] = scale
    figures["sensor_pose"] = [float(value) for value in mount]
    seen = _pooled_geometry(runs, mount)
    measured = seen["range"][keep]
    residual = np.abs(measured - scale * seen[kind][keep])
    # E|e| = sqrt(2/pi) std for a Gaussian e: fit std = a + b range on |e|, the range as
    # measured (LandmarkModel.R takes the measured one)
    coefficients, _ = nnls(np.column_stack([np.ones_like(measured), measured]),
                           residual / math.sqrt(2 / math.pi))
    figures["range_std"] = max(float(coefficients[0]), MIN_RANGE_STD)
    figures["range_std_per_m"] = float(coefficients[1])
    figures["bearing_std"] = _rms(_wrap(seen["bearing"] - seen["true_bearing"])[keep])
    return figures


def _rms(values: np.ndarray) -> float:
    return float(np.sqrt(np.mean(values ** 2)))


def _commanded(run: UtiasRun, starts: np.ndarray, delay: float) -> np.ndarray:
    """Integrals over [start, start + WINDOW_S] of the commanded v, w, |w| with the
    robot following each command ``delay`` seconds after its stamp."""
    odometry = run.odometry
    stamps = odometry[:, 0] + delay
    step = 0.01
    grid = np.arange(starts[0], starts[-1] + WINDOW_S + step, step)
    index = np.searchsorted(stamps, grid, side="right") - 1
    speeds = np.where(index[:, None] >= 0, odometry[np.maximum(index, 0), 1:3], 0.0)
    speeds = np.column_stack([speeds, np.abs(speeds[:, 1]), np.abs(speeds[:, 0])])
    cumulative = np.vstack([np.zeros(4), np.cumsum(speeds[:-1] * step, axis=0)])
    at = lambda t: np.column_stack([np.interp(t, grid, c) for c in cumulative.T])  # noqa: E731
    return at(starts + WINDOW_S) - at(starts)


def _windows(run: UtiasRun) -> np.ndarray:
    first = max(run.truth[0, 0], run.odometry[0, 0]) + 1.0
    last = min(run.truth[-1, 0], run.odometry[-1, 0]) - WINDOW_S - 1.0
    return np.arange(first, last, WINDOW_S / 2)


def _true_motion(run: UtiasRun, starts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The distance driven forward and the turn of each window: Vicon's steps, each along
    the heading of its moment, summed (a window's chord would be short on a curve)."""
    truth = run.truth
    heading = np.unwrap(truth[:, 3])
    along = 0.5 * (heading[1:] + heading[:-1])
    steps = np.diff(truth[:, 1]) * np.cos(along) + np.diff(truth[:, 2]) * np.sin(along)
    driven = np.concatenate([[0.0], np.cumsum(steps)])
    forward = np.interp(starts + WINDOW_S, truth[:, 0], driven) \
        - np.interp(starts, truth[:, 0], driven)
    begin, end = _truth_at(run, starts), _truth_at(run, starts + WINDOW_S)
    return forward, end[:, 2] - begin[:, 2]


def odometry_figures(runs: Sequence[UtiasRun]) -> dict[str, float]:
    """Delay, scales and the noise.* variances of the commanded odometry."""
    motion = [(_windows(run), *_true_motion(run, _windows(run))) for run in runs]

    def pooled(delay: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        commanded = np.vstack([_commanded(run, starts, delay)
                               for run, (starts, _, _) in zip(runs, motion)])
        forward = np.concatenate([m[1] for m in motion])
        turn = np.concatenate([m[2] for m in motion])
        return commanded, forward, turn

    def turn_misfit(delay: float) -> float:
        commanded, _, turn = pooled(delay)
        scale = commanded[:, 1] @ turn / (commanded[:, 1] @ commanded[:, 1])
        return float(np.mean((turn - scale * commanded[:, 1]) ** 2))

    delay = float(min(DELAYS, key=turn_misfit))
    commanded, forward, turn = pooled(delay)
    forward_scale = float(commanded[:, 0] @ forward / (commanded[:, 0] @ commanded[:, 0]))
    turn_scale = float(commanded[:, 1] @ turn / (commanded[:, 1] @ commanded[:, 1]))
    # The filter's step variances, var = per_m |d| + per_rad |phi| + per_s dt, with the
    # distance and turn the robot drove (the scaled commands); variances add over steps.
    # The distance's error is fitted per metre and the turn's per radian and per second
    # only: distance, turn and time grow together, and with all three terms free the
    # fit trades one for another from one robot to the next.
    distance = forward_scale * commanded[:, 3]
    turned = turn_scale * commanded[:, 2]
    distance_error = forward - forward_scale * commanded[:, 0]
    turn_error = turn - turn_scale * commanded[:, 1]
    per_m, _ = nnls(distance[:, None], distance_error ** 2)
    rotation, _ = nnls(np.column_stack([turned, np.full(len(turned), WINDOW_S)]),
                       turn_error ** 2)
    noise = {"noise.translation_per_m": float(per_m[0]), "noise.translation_per_rad": 0.0,
             "noise.translation_per_s": 0.0, "noise.rotation_per_m": 0.0,
             "noise.rotation_per_rad": float(rotation[0]),
             "noise.rotation_per_s": float(rotation[1])}
    return {"odometry_delay": delay, "forward_scale": forward_scale, "turn_scale": turn_scale,
            **noise, "windows": float(len(commanded))}


def calibrate(runs: Sequence[UtiasRun]) -> dict[str, object]:
    """The ekf_localizer parameters these robots' data give (see the module's text)."""
    camera, odometry = camera_figures(runs), odometry_figures(runs)
    return {
        "range_model": camera["range_model"], "range_scale": camera["range_scale"],
        "sensor_pose": camera["sensor_pose"], "range_std": camera["range_std"],
        "range_std_per_m": camera["range_std_per_m"],
        "bearing_std": camera["bearing_std"],
        "odometry_delay": odometry["odometry_delay"],
        "odometry_scale": [odometry["forward_scale"], odometry["turn_scale"]],
        **{name: value for name, value in odometry.items() if name.startswith("noise.")},
        **fleet_spread(runs),
    }


def fleet_spread(runs: Sequence[UtiasRun]) -> dict[str, object]:
    """How far one robot's camera is from the pooled calibration: the spread (sample
    std) of each robot's own range scale and mount, as the filter's range_scale_std and
    sensor_pose_std; nothing from fewer than two robots (no spread to measure)."""
    if len(runs) < 2:
        return {}
    own = [camera_figures([run]) for run in runs]
    scales = np.array([figures["range_scale"] for figures in own])
    mounts = np.array([figures["sensor_pose"] for figures in own])
    return {"range_scale_std": float(np.std(scales, ddof=1)),
            "sensor_pose_std": [float(v) for v in np.std(mounts, axis=0, ddof=1)]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--dataset", type=Path, default=DATASET)
    parser.add_argument("--robots", type=int, nargs="+", default=[1, 2, 3])
    args = parser.parse_args()
    if not args.dataset.is_dir():
        sys.exit(f"utias_calibration: no dataset at {args.dataset} "
                 f"(see ../shared/data/README.md)")
    runs = [read_run(args.dataset, robot) for robot in args.robots]
    if not runs:
        sys.exit("utias_calibration: give at least one robot")
    camera, odometry = camera_figures(runs), odometry_figures(runs)
    print(f"robots {args.robots} of {args.dataset.name}")
    print(f"camera: {camera['observations']:.0f} landmark observations, "
          f"{camera['outliers']:.0f} left out (bearing > {OUTLIER_BEARING} rad off)")
    for kind in ("distance", "depth"):
        print(f"  range = {camera[f'{kind}_scale']:.4f} x true {kind}: residual rms "
              f"{camera[f'{kind}_residual_std']:.4f} m")
    print(f"  range std = {camera['range_std']:.4f} + {camera['range_std_per_m']:.4f} "
          f"x range; bearing std {camera['bearing_std']:.4f} rad")
    print(f"odometry: {odometry['windows']:.0f} windows of {WINDOW_S:g} s; followed "
          f"{odometry['odometry_delay']:.2f} s late; drives {odometry['forward_scale']:.3f} "
          f"of the forward and {odometry['turn_scale']:.3f} of the turn speed commanded")
    print("parameters (ekf_localizer):")
    for name, value in calibrate(runs).items():
        shown = [round(v, 5) for v in value] if isinstance(value, list) else (
            value if isinstance(value, str) else f"{value:.4g}")
        print(f"  {name}: {shown}")


if __name__ == "__main__":
    main()
