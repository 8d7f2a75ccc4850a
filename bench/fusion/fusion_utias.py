"""ekf_node's filter on the UTIAS robots' odometry alone: does its covariance hold the truth?

    python bench/fusion/fusion_utias.py [--dataset DIR] [--fit-robot 1] [--robots 1 2 3]

Each robot's commands (t, v, w at about 65 Hz; ../shared/data/utias, dataset 7) are fed
as a twist input (vx = v, vy = 0: the robot does not slide; vyaw = w) through the fusion
core as ekf_node runs it (tools/fusion/offline.py), in two_d_mode, from Vicon's pose at
the first command. At every periodic output (30 Hz) within Vicon's span, the truth's
(x, y) is compared with the estimate: the squared Mahalanobis distance under the
position's covariance, and the share of outputs within the 95% ellipse (at most 5.991,
chi-square with 2 degrees of freedom), over the whole run and over each third.

The noise figures come from one robot's data against Vicon (``--fit-robot``), the
others being the validation; nothing is tuned to the share:
- the twist's variances (its messages' covariance): the mean square of Vicon's forward
  and turn speeds (differenced over 0.1 s) less the commanded ones, vy's as vx's;
- the pose's process noise (per second): x and y from dead reckoning's position error
  over 5 s windows (its variance per axis, over the window's length); yaw by least
  squares of dead reckoning's heading-error variance against the window's length, over
  windows of 5 s to 320 s, the horizons a run on odometry alone spans (it grows faster
  than a random walk's would: the robots' turns are biased, not only noisy);
- every other entry: the peer's defaults.

A third table asks what one run's share can say: runs of a robot drawn as the filter
believes it moves (its commands off by the twist's variances, its heading and position
walking by the process noise; ``own_model_shares``), scored against this run's outputs.
The errors of one run accumulate, so its share is not a fraction of independent trials:
how widely it spreads when the model is right is what the table shows.
Nothing is asserted here; tests/unit/test_fusion_consistency.py checks one robot.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace

import numpy as np

sys.path.insert(1, str(Path(__file__).resolve().parents[2]))  # the repository: bench
from bench.common import SHARED_DATA, table  # noqa: E402

from estimation_nodes.params.fusion import fusion_config  # noqa: E402
from estimation_nodes.tools.fusion import offline  # noqa: E402
from estimation_nodes.tools.importers.utias import UtiasRun, read_run  # noqa: E402

DATASET = SHARED_DATA / "utias" / "MRCLAM_Dataset7"
#: Window lengths (s) of the heading's fit: 5 s to about a third of a run.
HEADING_WINDOWS = (5.0, 10.0, 20.0, 40.0, 80.0, 160.0, 320.0)
#: Window length (s) of the position's fit: short, where the heading's error adds little.
POSITION_WINDOW = 5.0
#: Seconds over which Vicon's poses are differenced into speeds.
SPEED_SPAN = 0.1
#: The 95% quantile of chi-square with 2 degrees of freedom.
ELLIPSE_95 = 5.991
#: The peer's default process_noise_covariance diagonal (per second).
PEER_PROCESS_NOISE = (0.05, 0.05, 0.06, 0.03, 0.03, 0.06, 0.025, 0.025, 0.04, 0.01, 0.01,
                      0.02, 0.01, 0.01, 0.015)
#: The filter's update rate (Hz): the peer's default.
FREQUENCY = 30.0


@dataclass(frozen=True)
class NoiseFigures:
    """What the filter is told of the odometry, derived from one robot's data."""

    #: The twist's variances: forward (and sideways) speed (m^2/s^2), turn rate (rad^2/s^2).
    speed_variance: float
    turn_variance: float
    #: Process noise (per second): x and y each (m^2/s), yaw (rad^2/s).
    position_rate: float
    heading_rate: float


def truth_at(run: UtiasRun, times: np.ndarray) -> np.ndarray:
    """Vicon's x, y and heading (unwrapped) at ``times``, interpolated."""
    truth = run.truth
    return np.column_stack([np.interp(times, truth[:, 0], truth[:, 1]),
                            np.interp(times, truth[:, 0], truth[:, 2]),
                            np.interp(times, truth[:, 0], np.unwrap(truth[:, 3]))])


def dead_reckoning_errors(run: UtiasRun, window: float) -> np.ndarray:
    """Per window (starts ``window`` / 2 apart): the truth at its end less the commands
    driven from the truth at its start, in the start's frame (along, across, heading)."""
    odometry = run.odometry
    first = max(run.truth[0, 0], odometry[0, 0]) + 1.0
    last = min(run.truth[-1, 0], odometry[-1, 0]) - window - 1.0
    starts = np.arange(first, last, window / 2)
    begins, ends = truth_at(run, starts), truth_at(run, starts + window)
    errors = []
    for start, begin, end in zip(starts, begins, ends):
        a = max(np.searchsorted(odometry[:, 0], start, side="right") - 1, 0)
        b = np.searchsorted(odometry[:, 0], start + window, side="right")
        # each command held until the next one, within the window (midpoint headings)
        times = np.clip(np.r_[odometry[a:b, 0], start + window], start, start + window)
        dt = np.diff(times)
        v, w = odometry[a:b, 1], odometry[a:b, 2]
        heading = begin[2] + np.r_[0.0, np.cumsum(w * dt)][:-1] + 0.5 * w * dt
        driven = np.array([begin[0] + np.sum(v * dt * np.cos(heading)),
                           begin[1] + np.sum(v * dt * np.sin(heading)),
                           begin[2] + np.sum(w * dt)])
        error = end - driven
        c, s = math.cos(begin[2]), math.sin(begin[2])
        errors.append([c * error[0] + s * error[1], -s * error[0] + c * error[1], error[2]])
    return np.array(errors)


def speed_errors(run: UtiasRun) -> tuple[np.ndarray, np.ndarray]:
    """Vicon's forward speed and turn rate at each command less the command's."""
    odometry, half = run.odometry, SPEED_SPAN / 2
    inside = (odometry[:, 0] > run.truth[0, 0] + half) & \
        (odometry[:, 0] < run.truth[-1, 0] - half)
    times, commanded = odometry[inside, 0], odometry[inside]
    before, after = truth_at(run, times - half), truth_at(run, times + half)
    heading = 0.5 * (before[:, 2] + after[:, 2])
    moved = (after - before) / SPEED_SPAN
    forward = moved[:, 0] * np.cos(heading) + moved[:, 1] * np.sin(heading)
    return forward - commanded[:, 1], moved[:, 2] - commanded[:, 2]


def fit(run: UtiasRun) -> NoiseFigures:
    """The noise figures of one robot's data (the module's text says how)."""
    forward, turn = speed_errors(run)
    short = dead_reckoning_errors(run, POSITION_WINDOW)
    windows = np.array(HEADING_WINDOWS)
    heading_variance = np.array([np.mean(dead_reckoning_errors(run, window)[:, 2] ** 2)
                                 for window in windows])
    return NoiseFigures(
        speed_variance=float(np.mean(forward ** 2)), turn_variance=float(np.mean(turn ** 2)),
        position_rate=float(np.mean(short[:, 0] ** 2 + short[:, 1] ** 2) / 2
                            / POSITION_WINDOW),
        heading_rate=float(windows @ heading_variance / (windows @ windows)))


def parameters(figures: NoiseFigures, start: np.ndarray) -> dict:
    """ekf_node's parameters (the peer's names) for a robot starting at ``start``
    (x, y, heading)."""
    process_noise = np.diag(PEER_PROCESS_NOISE)
    process_noise[0, 0] = process_noise[1, 1] = figures.position_rate
    process_noise[5, 5] = figures.heading_rate
    initial = np.zeros(15)
    initial[[0, 1, 5]] = start
    return {"frequency": FREQUENCY, "two_d_mode": True, "twist0": "cmd_twist",
            "twist0_config": [False] * 6 + [True, True, False, False, False, True]
            + [False] * 3,
            "process_noise_covariance": [float(v) for v in process_noise.ravel()],
            # it starts where Vicon has it: the peer's default, nearly nil, initial covariance
            "initial_state": [float(v) for v in initial]}


def twist_messages(run: UtiasRun, figures: NoiseFigures) -> Iterator[tuple[int, str, object]]:
    """(stamp ns, topic, message) of each command, as a TwistWithCovarianceStamped would
    carry it."""
    covariance = np.zeros((6, 6))
    covariance[0, 0] = covariance[1, 1] = figures.speed_variance
    covariance[5, 5] = figures.turn_variance
    covariance[2, 2] = covariance[3, 3] = covariance[4, 4] = 1e-6   # two_d_mode's zeros
    flat = covariance.ravel()
    for t, v, w in run.odometry.tolist():
        stamp = round(t * 1e9)
        header = SimpleNamespace(stamp=SimpleNamespace(sec=stamp // 10**9,
                                                       nanosec=stamp % 10**9),
                                 frame_id="base_link")
        twist = SimpleNamespace(linear=SimpleNamespace(x=v, y=0.0, z=0.0),
                                angular=SimpleNamespace(x=0.0, y=0.0, z=w))
        yield stamp, "cmd_twist", SimpleNamespace(
            header=header, twist=SimpleNamespace(twist=twist, covariance=flat))


@dataclass(frozen=True)
class HeadingDrift:
    """How a robot's commanded heading goes wrong over the longest window: a steady turn
    bias (the mean error over the window's length) and a random walk about it."""

    window: float
    #: The mean heading error over the window's length (rad/s): a bias of the turn rate.
    bias: float
    #: The error's variance about that mean, over the window's length (rad^2/s).
    walk_rate: float
    #: The variance as a random walk's (mean included), what the yaw's process noise holds.
    total_rate: float


def heading_drift(run: UtiasRun, window: float = HEADING_WINDOWS[-1]) -> HeadingDrift:
    errors = dead_reckoning_errors(run, window)[:, 2]
    return HeadingDrift(window, float(np.mean(errors)) / window,
                        float(np.var(errors)) / window, float(np.mean(errors ** 2)) / window)


@dataclass(frozen=True)
class Consistency:
    """How a run's estimates and covariances held the truth."""

    outputs: int
    #: The share of outputs with the truth in the 95% ellipse: all, and per third.
    share: float
    thirds: tuple[float, float, float]
    #: At the last output: the position error (m) and sqrt(var x + var y) (m).
    final_error: float
    final_spread: float
    #: Each output scored: its time (s), the position's estimate and covariance (for
    #: ``own_model_shares``).
    times: np.ndarray
    estimates: np.ndarray
    covariances: np.ndarray


def consistency(run: UtiasRun, figures: NoiseFigures) -> Consistency:
    """The robot's commands through the filter, its outputs against Vicon."""
    start = truth_at(run, run.odometry[:1, 0])[0]
    start[2] = math.remainder(start[2], 2 * math.pi)
    config = fusion_config(parameters(figures, start), "ekf")
    result = offline.run(config, twist_messages(run, figures), keep_covariances=True)
    times = np.array([stamp for stamp, _ in result.outputs]) * 1e-9
    inside = (times >= run.truth[0, 0]) & (times <= run.truth[-1, 0])
    estimates = np.array([x[:2] for _, x in result.outputs])[inside]
    covariances = np.array([p[:2, :2] for p in result.covariances])[inside]
    errors = truth_at(run, times[inside])[:, :2] - estimates
    squared = np.einsum("ni,nij,nj->n", errors, np.linalg.inv(covariances), errors)
    held = squared <= ELLIPSE_95
    third = len(held) // 3
    return Consistency(
        outputs=len(held), share=float(np.mean(held)),
        thirds=tuple(float(np.mean(held[k * third:(k + 1) * third])) for k in range(3)),
        final_error=float(np.hypot(*errors[-1])),
        final_spread=float(math.sqrt(covariances[-1, 0, 0] + covariances[-1, 1, 1])),
        times=times[inside], estimates=estimates, covariances=covariances)


def own_model_shares(run: UtiasRun, figures: NoiseFigures, result: Consistency, runs: int,
                     seed: int = 1) -> np.ndarray:
    """The share of outputs inside the 95% ellipse in each of ``runs`` drawn runs of a
    robot that moves as the filter believes: each command's speed and turn off the true
    ones by the twist's variances (independent per command), the heading and the position
    walking by the process noise, from the filter's start. The filter's estimates and
    covariances are this run's (they depend on the commands alone)."""
    rng = np.random.default_rng(seed)
    commands = run.odometry
    dt = np.diff(commands[:, 0], append=commands[-1, 0])
    start = truth_at(run, commands[:1, 0])[0]
    heading = np.full(runs, start[2])
    position = np.tile(start[:2], (runs, 1))
    truths = np.empty((len(commands), runs, 2))
    for k, ((_, v, w), step) in enumerate(zip(commands.tolist(), dt.tolist())):
        truths[k] = position
        speed = v + rng.normal(0.0, math.sqrt(figures.speed_variance), runs)
        turn = w + rng.normal(0.0, math.sqrt(figures.turn_variance), runs)
        position = position + (speed * step)[:, None] * np.column_stack(
            [np.cos(heading), np.sin(heading)]) + rng.normal(
            0.0, math.sqrt(figures.position_rate * step), (runs, 2))
        heading = heading + turn * step + rng.normal(0.0, math.sqrt(figures.heading_rate * step),
                                                     runs)
    # The truth at each output: the last command's at or before it.
    at = np.searchsorted(commands[:, 0], result.times, side="right") - 1
    errors = truths[np.clip(at, 0, None)] - result.estimates[:, None, :]
    squared = np.einsum("nri,nij,nrj->nr", errors, np.linalg.inv(result.covariances), errors)
    return np.mean(squared <= ELLIPSE_95, axis=0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--dataset", type=Path, default=DATASET)
    parser.add_argument("--fit-robot", type=int, default=1,
                        help="the robot whose data give the noise figures (1)")
    parser.add_argument("--robots", type=int, nargs="+", default=[1, 2, 3])
    parser.add_argument("--model-runs", type=int, default=400,
                        help="runs drawn per robot for the share under the filter's own "
                             "covariance (0: none)")
    args = parser.parse_args()
    if not args.dataset.is_dir():
        sys.exit(f"fusion_utias: no dataset at {args.dataset} (see ../shared/data/README.md)")
    figures = fit(read_run(args.dataset, args.fit_robot))
    print(f"noise figures from robot {args.fit_robot}: twist variances "
          f"{figures.speed_variance:.3g} m^2/s^2 (vx, vy), {figures.turn_variance:.3g} "
          f"rad^2/s^2 (vyaw); process noise {figures.position_rate:.3g} m^2/s (x, y), "
          f"{figures.heading_rate:.3g} rad^2/s (yaw)")
    rows, results = [], {}
    for robot in args.robots:
        result = results[robot] = consistency(read_run(args.dataset, robot), figures)
        rows.append([str(robot), "fitted" if robot == args.fit_robot else "validation",
                     str(result.outputs), f"{100 * result.share:.1f}%",
                     " / ".join(f"{100 * share:.0f}%" for share in result.thirds),
                     f"{result.final_error:.2f}", f"{result.final_spread:.2f}"])
    rows += pooled_rows(results, args.fit_robot)
    print("ekf_node's filter on the commands alone (two_d_mode, twist at ~65 Hz, outputs at "
          f"{FREQUENCY:g} Hz): truth (x, y) within the 95% ellipse (d^2 <= {ELLIPSE_95})")
    print(table(["robot", "noise figures", "outputs", "in the 95% ellipse",
                 "by thirds of the run", "final error m", "final sqrt(trace P_xy) m"],
                rows))
    drifts = [(robot, heading_drift(read_run(args.dataset, robot))) for robot in args.robots]
    print(f"\nthe commanded heading's error over {drifts[0][1].window:g} s windows: a steady "
          "turn bias and a random walk about it (the yaw's process noise is one rate for "
          "both)")
    print(table(["robot", "turn bias mrad/s", "random walk rad^2/s", "as one rate rad^2/s"],
                [[str(robot), f"{1e3 * drift.bias:+.2f}", f"{drift.walk_rate:.4f}",
                  f"{drift.total_rate:.4f}"] for robot, drift in drifts]))
    if args.model_runs:
        print_own_model_shares(args.dataset, figures, results, args.model_runs)


def pooled_rows(results: dict[int, Consistency], fitted: int) -> list[list[str]]:
    """The share over every robot's outputs together, and over the validation robots'."""
    groups = [("all", list(results)),
              ("validation", [robot for robot in results if robot != fitted])]
    rows = []
    for name, robots in groups:
        if len(robots) < 2:
            continue
        outputs = sum(results[robot].outputs for robot in robots)
        held = sum(results[robot].share * results[robot].outputs for robot in robots)
        rows.append([f"{name} ({', '.join(map(str, robots))})", "pooled", str(outputs),
                     f"{100 * held / outputs:.1f}%", "", "", ""])
    return rows


def print_own_model_shares(dataset: Path, figures: NoiseFigures,
                           results: dict[int, Consistency], runs: int) -> None:
    rows = []
    for robot, result in results.items():
        shares = own_model_shares(read_run(dataset, robot), figures, result, runs)
        rows.append([str(robot), f"{100 * result.share:.1f}%",
                     f"{100 * np.mean(shares):.1f}%",
                     " / ".join(f"{100 * q:.1f}%" for q in np.quantile(shares, [0.05, 0.5])),
                     f"{100 * np.mean((shares >= 0.85) & (shares <= 0.99)):.0f}%",
                     f"{100 * np.mean(shares > 0.99):.0f}%",
                     f"{100 * np.mean(shares >= 1.0):.0f}%",
                     f"{100 * np.mean(shares <= result.share):.0f}%"])
    print(f"\nif the robot moved as the filter believes ({runs} drawn runs per robot, the "
          "filter's outputs this run's): the share one run shows")
    print(table(["robot", "this run", "mean of the drawn", "5th / 50th percentile",
                 "drawn within 85..99%", "drawn above 99%", "drawn at 100%",
                 "drawn at or below this run"], rows))


if __name__ == "__main__":
    main()
