"""The landmark EKF and UKF on a real robot: UTIAS dataset 7, scored against Vicon.

For each robot, the whole run through the core filter (no DDS): position and
heading RMSE against the motion-capture truth, how often the truth lies in the
estimate's 95% position ellipse, the longest stretch farther than 0.5 m from the
truth, and the time the whole run takes. Dead reckoning (odometry alone) and the
textbook EKF (no gate, no recovery, the package's default models) run beside them on
the same data, and a floor: the truth itself at every camera frame, carried to the
next by odometry (between frames no filter knows more than the pose at the last).

The filters take the parameters ekf_localizer takes from ``--params`` (by default
msgs_config/robots/utias_mrclam.yaml, whose figures bench/landmarks/utias_calibration.py derives
from robots 1 to 3 pooled). With ``--cross-validate`` each robot is run with the
figures derived from the other robots alone (the file's other settings kept): what a
robot the figures never saw gets (the spreads, range_scale_std and sensor_pose_std, then
come from two robots' calibrations; with only two robots given, from the file).
``--truth-shift S`` scores against Vicon's poses S seconds later than their stamps (a
question about the clocks, not a filter's figure).

    python bench/landmarks/ekf_real.py [--dataset DIR] [--robots 1 2 3] [--params FILE]
                             [--cross-validate] [--truth-shift S]
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(1, str(Path(__file__).resolve().parents[2]))  # the repository: bench
from bench.common import REPO, SHARED_DATA, table  # noqa: E402

from estimation_nodes.core.kalman import landmarks as lm  # noqa: E402
from estimation_nodes.core.kalman.landmarks import LandmarkLocalization, Observation  # noqa: E402
from bench.landmarks.utias_calibration import calibrate  # noqa: E402

from estimation_nodes.params.landmarks import default_landmark_model, landmark_model  # noqa: E402
from estimation_nodes.params.param_files import read_node_parameters  # noqa: E402
from estimation_nodes.params.specs import LANDMARK_MODEL_SPECS, spec_defaults  # noqa: E402
from estimation_nodes.tools.importers.utias import read_run  # noqa: E402

DATASET = SHARED_DATA / "utias" / "MRCLAM_Dataset7"
PARAMS = REPO / "msgs_config" / "robots" / "utias_mrclam.yaml"
#: The covariance every run starts with (it starts at the truth's first pose).
INITIAL_COVARIANCE = np.diag([0.01, 0.01, 0.01])
#: Truth samples scored per second (Vicon gives about 60).
SCORE_HZ = 10.0
#: Position NEES bound of the 95% ellipse: the chi-square (2 dof) 0.95 quantile.
ELLIPSE_95 = lm.chi_square_2_quantile(0.95)


def truth_at(run, t: float) -> np.ndarray:
    """Vicon's pose at ``t`` (interpolated; the heading through its shorter way)."""
    truth = run.truth
    i = min(max(int(np.searchsorted(truth[:, 0], t)), 1), len(truth) - 1)
    (t0, *a), (t1, *b) = truth[i - 1], truth[i]
    share = 0.0 if t1 == t0 else min(max((t - t0) / (t1 - t0), 0.0), 1.0)
    turn = (b[2] - a[2] + math.pi) % (2 * math.pi) - math.pi
    return np.array([a[0] + share * (b[0] - a[0]), a[1] + share * (b[1] - a[1]),
                     a[2] + share * turn])


def run_filter(run, model, initial_covariance, correct: bool | str = True):
    """The estimate after every event: times, poses, covariances; and the wall time.
    ``correct`` False: odometry alone; "oracle": at every camera frame the pose is set
    to the truth, and odometry carries it to the next (no filter can do better between
    frames than to know the pose exactly at the last one)."""
    first = run.truth[0]
    localization = LandmarkLocalization(model, first[1:], initial_covariance, first[0])
    frames = run.frames() if correct else []
    events = sorted([(t, 0, i) for i, t in enumerate(run.odometry[:, 0])]
                    + [(t, 1, i) for i, (t, _) in enumerate(frames)])
    times, poses, covariances = [], [], []
    started = time.perf_counter()
    for t, kind, index in events:
        if kind == 0:
            _, v, w = run.odometry[index]
            localization.on_odometry(t, v, w)
        elif correct == "oracle":
            localization.on_frame(t, [])
            localization.x = np.append(truth_at(run, t), localization.x[3:])
        else:
            localization.on_frame(t, [Observation(int(s), r, b)
                                      for _, s, r, b in frames[index][1]])
        times.append(t)
        poses.append(localization.pose)
        covariances.append(localization.pose_covariance)
    elapsed = time.perf_counter() - started
    return np.array(times), np.array(poses), np.array(covariances), elapsed, localization


def score(run, times, poses, covariances) -> dict:
    truth = run.truth[(run.truth[:, 0] >= times[0])]
    step = max(1, int(round(len(truth) / ((truth[-1, 0] - truth[0, 0]) * SCORE_HZ))))
    truth = truth[::step]
    index = np.searchsorted(times, truth[:, 0], side="right") - 1
    keep = index >= 0
    truth, index = truth[keep], index[keep]
    error = poses[index, :2] - truth[:, 1:3]
    heading = (poses[index, 2] - truth[:, 3] + math.pi) % (2 * math.pi) - math.pi
    distance = np.hypot(error[:, 0], error[:, 1])
    blocks = covariances[index, :2, :2]
    nees = np.einsum("ni,nij,nj->n", error, np.linalg.inv(blocks), error)
    return {"position_rmse": float(np.sqrt(np.mean(distance ** 2))),
            "heading_rmse_deg": math.degrees(float(np.sqrt(np.mean(heading ** 2)))),
            "in_ellipse": float(np.mean(nees <= ELLIPSE_95)),
            "longest_off_s": _longest_stretch(truth[:, 0], distance > 0.5)}


def _longest_stretch(times: np.ndarray, off: np.ndarray) -> float:
    longest, start = 0.0, None
    for t, bad in zip(times, off):
        if bad and start is None:
            start = t
        elif not bad and start is not None:
            longest, start = max(longest, t - start), None
    if start is not None:
        longest = max(longest, times[-1] - start)
    return longest


def filters(run, figures: dict) -> list[tuple[str, object, bool]]:
    """(name, model, whether it corrects) of each filter in the table, for ``run``."""
    textbook = replace(default_landmark_model("ekf", run.landmarks), gate_probability=1.0,
                       range_std=0.12, range_std_per_m=0.0)
    tuned = {**spec_defaults(LANDMARK_MODEL_SPECS), **figures}
    return [("dead reckoning", landmark_model({**tuned, "filter": "ekf"}, run.landmarks),
             False),
            ("truth at every frame", landmark_model({**tuned, "filter": "ekf"},
                                                     run.landmarks), "oracle"),
            ("textbook EKF", textbook, True),
            ("EKF", landmark_model({**tuned, "filter": "ekf"}, run.landmarks), True),
            ("UKF", landmark_model({**tuned, "filter": "ukf"}, run.landmarks), True)]


def file_figures(path: Path) -> dict:
    """The landmark-model parameters the file gives ekf_localizer."""
    values = read_node_parameters(path.read_text(encoding="utf-8"), "/ekf_localizer")
    names = {spec.name for spec in LANDMARK_MODEL_SPECS} - {"filter"}
    return {name: value for name, value in values.items() if name in names}


def shifted(run, seconds: float):
    """The run with Vicon's stamps ``seconds`` later."""
    if not seconds:
        return run
    truth = run.truth.copy()
    truth[:, 0] += seconds
    return replace(run, truth=truth)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--dataset", type=Path, default=DATASET)
    parser.add_argument("--robots", type=int, nargs="+", default=[1, 2, 3])
    parser.add_argument("--params", type=Path, default=PARAMS)
    parser.add_argument("--truth-shift", type=float, default=0.0, metavar="S",
                        help="score against Vicon's poses S seconds later than stamped")
    parser.add_argument("--cross-validate", action="store_true",
                        help="run each robot with the figures of the other robots")
    args = parser.parse_args()
    if not args.dataset.is_dir():
        sys.exit(f"ekf_real: no dataset at {args.dataset} (see ../shared/data/README.md)")
    if args.cross_validate and len(set(args.robots)) < 2:
        sys.exit("ekf_real: --cross-validate needs two robots or more")
    runs = {robot: read_run(args.dataset, robot) for robot in args.robots}
    rows = []
    for robot, run in runs.items():
        figures = file_figures(args.params)
        if args.cross_validate:
            # the file's choices (the iterated EKF's passes) stay; its figures are
            # derived again without this robot
            others = [other for number, other in runs.items() if number != robot]
            figures.update(calibrate(others))
        for name, model, correct in filters(run, figures):
            times, poses, covs, elapsed, loc = run_filter(run, model, INITIAL_COVARIANCE,
                                                          correct)
            s = score(shifted(run, args.truth_shift), times, poses, covs)
            # the floor's covariance is odometry's alone, never corrected: not scored
            in_ellipse = "-" if correct == "oracle" else f"{s['in_ellipse']:.0%}"
            scale, scale_std = loc.range_scale
            observed = scale_std and loc.counts.get("used")
            learned = f"{scale:.4f} +- {scale_std:.4f}" if observed else "-"
            rows.append([str(robot), name, f"{s['position_rmse']:.3f}",
                         f"{s['heading_rmse_deg']:.1f}", in_ellipse,
                         f"{s['longest_off_s']:.1f}", f"{elapsed:.2f}", learned,
                         ", ".join(f"{k} {v}" for k, v in sorted(loc.counts.items()))])
    source = "each robot with the figures of the others" if args.cross_validate \
        else str(args.params)
    print(f"parameters: {source}")
    print(table(["robot", "filter", "position RMSE (m)", "heading RMSE (deg)",
                 "truth in 95% ellipse", "longest > 0.5 m (s)", "run time (s)",
                 "range scale at the end", "counts"],
                rows))


if __name__ == "__main__":
    main()
