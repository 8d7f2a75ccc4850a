"""Render a run as one PNG: histogram beliefs per step and the Kalman estimate over time
(or, for a matrix run in the plane, the track with its 2-sigma ellipses).

    estimation_plot RUN.mcap --output run.png

Top: up to twelve steps (evenly spread over the run), each a panel with the
predicted (light) and corrected (dark) belief side by side over the cells,
as the textbook's figures of Examples 6.11 to 6.14 show them, and the true
cell marked. Bottom: the Kalman estimate with its 2-sigma band, the
measurements and the truth. Needs matplotlib (the ``plot`` extra).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from estimation_nodes.params import topics
from estimation_nodes.tools.recording.run_record import OUTPUT_LISTS, RunRecord

#: Pixel size of every picture: 16 x 12 inches at 100 dpi.
FIGURE_INCHES = (16.0, 12.0)
DPI = 100
MAX_PANELS = 12


def _chosen_steps(count: int) -> list[int]:
    if count <= MAX_PANELS:
        return list(range(count))
    return sorted({int(round(i)) for i in np.linspace(0, count - 1, MAX_PANELS)})


def _settled(record: RunRecord, topic: str) -> dict[int, int]:
    """Step -> index of the estimate on ``topic`` that settled it; in arrival order
    when the run has no truth to count steps by."""
    if record.truth or record.true_states:
        return record.per_step(topic)
    return {index: index for index in range(len(getattr(record, OUTPUT_LISTS[topic])))}


def _belief_panel(ax, record: RunRecord, step: int, corrected: int) -> None:
    cells = np.arange(record.cells)
    width = 0.4
    predicted = record.prediction_before(topics.BELIEF, corrected, topics.BELIEF_PREDICTED)
    if predicted is not None:
        ax.bar(cells - width / 2, record.predicted[predicted], width, color="#9ecae1",
               label="predicted")
    ax.bar(cells + width / 2, record.corrected[corrected], width, color="#08519c",
           label="corrected")
    if step < len(record.truth):
        true_cell = record.truth[step] % record.cells
        ax.axvline(true_cell, color="#d62728", linewidth=1.5, linestyle="--", label="true cell")
    ax.set_title(f"step {step + 1}", fontsize=10)
    ax.set_ylim(0.0, 1.0)
    if record.cells <= 25:
        ax.set_xticks(cells)
    ax.tick_params(labelsize=8)


def _kalman_panel(ax, record: RunRecord) -> None:
    settled = _settled(record, topics.KALMAN_ESTIMATE)
    if not settled:
        ax.text(0.5, 0.5, "no Kalman estimates in this run", ha="center", va="center",
                transform=ax.transAxes)
        return
    steps = np.array(list(settled)) + 1
    x = np.array([record.kalman[i][0] for i in settled.values()])
    sigma = np.sqrt([record.kalman[i][1] for i in settled.values()])
    ax.fill_between(steps, x - 2 * sigma, x + 2 * sigma, color="#c6dbef",
                    label="estimate +- 2 sigma")
    ax.plot(steps, x, color="#08519c", marker="o", label="Kalman estimate")
    if record.measurements:
        ax.plot(np.arange(1, len(record.measurements) + 1), record.measurements, "x",
                color="#ff7f0e", label="measurement")
    if record.truth:
        ax.plot(np.arange(1, len(record.truth) + 1), record.truth, color="#d62728",
                linestyle="--", label="truth")
    ax.set_xlabel("step")
    ax.set_ylabel("position (cells, unwrapped)")
    ax.legend(loc="upper left", fontsize=9)
    ax.grid(alpha=0.3)


def _ellipse_points(mean: np.ndarray, covariance: np.ndarray, sigmas: float = 2.0,
                    points: int = 60) -> np.ndarray:
    """Points on the ``sigmas`` contour of a 2-D Gaussian."""
    values, vectors = np.linalg.eigh(covariance)
    angles = np.linspace(0.0, 2.0 * np.pi, points)
    circle = np.stack([np.cos(angles), np.sin(angles)])
    return (mean[:, None] + vectors @ (sigmas * np.sqrt(np.maximum(values, 0.0))[:, None]
                                        * circle)).T


def _tracking_panels(figure, record: RunRecord) -> None:
    """A matrix run in the plane: state components 0 and 1 as x and y."""
    track = figure.add_subplot(1, 2, 1)
    estimates = np.array([x[:2] for x, _ in record.states])
    if record.true_states:
        truth = np.array([x[:2] for x in record.true_states])
        track.plot(truth[:, 0], truth[:, 1], color="#d62728", linestyle="--", label="truth")
    if record.kalman_measurements and len(record.kalman_measurements[0]) >= 2:
        z = np.array([m[:2] for m in record.kalman_measurements])
        track.plot(z[:, 0], z[:, 1], "x", color="#ff7f0e", label="measurement")
    track.plot(estimates[:, 0], estimates[:, 1], color="#08519c", marker="o", markersize=3,
               label="Kalman estimate")
    for index, (x, P) in enumerate(record.states):
        ellipse = _ellipse_points(x[:2], P[:2, :2])
        track.plot(ellipse[:, 0], ellipse[:, 1], color="#6baed6", linewidth=0.8,
                   label="2-sigma ellipse" if index == 0 else None)
    track.set_aspect("equal", adjustable="datalim")
    track.set_xlabel("x")
    track.set_ylabel("y")
    track.set_title("track in the plane")
    track.legend(loc="best", fontsize=9)
    track.grid(alpha=0.3)
    errors = figure.add_subplot(1, 2, 2)
    settled = _settled(record, topics.KALMAN_STATE)
    steps = np.array(list(settled)) + 1
    if record.true_states:
        error = [np.linalg.norm(record.states[i][0][:2] - record.true_states[step][:2])
                 for step, i in settled.items()]
        errors.plot(steps, error, color="#08519c", label="|estimate - truth|")
    sigma = [np.sqrt(np.trace(record.states[i][1][:2, :2])) for i in settled.values()]
    errors.plot(steps, sigma, color="#6baed6", linestyle=":", label="sqrt(trace P), position")
    errors.set_xlabel("step")
    errors.set_ylabel("position error")
    errors.set_title("position error and its predicted size")
    errors.legend(loc="best", fontsize=9)
    errors.grid(alpha=0.3)


def render(record: RunRecord, output: Path) -> Path:
    """Write the picture of ``record`` to ``output`` (PNG, 1600 x 1200 pixels)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure = plt.figure(figsize=FIGURE_INCHES, dpi=DPI)
    if record.states and record.states[0][0].size >= 2:
        _tracking_panels(figure, record)
        figure.suptitle("estimation_nodes: matrix Kalman filter, tracking in the plane",
                        fontsize=13)
        return _save(figure, output, plt)
    grid = figure.add_gridspec(4, 4, height_ratios=[1, 1, 1, 1.6], hspace=0.45, wspace=0.25)
    settled = _settled(record, topics.BELIEF)
    steps = [list(settled)[i] for i in _chosen_steps(len(settled))]
    for panel, step in enumerate(steps):
        _belief_panel(figure.add_subplot(grid[panel // 4, panel % 4]), record, step,
                      settled[step])
    if not steps:
        ax = figure.add_subplot(grid[0, :])
        ax.text(0.5, 0.5, "no histogram beliefs in this run", ha="center", va="center")
        ax.axis("off")
    elif figure.axes:
        figure.axes[0].legend(fontsize=8, loc="upper right")
    _kalman_panel(figure.add_subplot(grid[3, :]), record)
    figure.suptitle("estimation_nodes: histogram belief per step (top) and Kalman estimate "
                    "(bottom)", fontsize=13)
    return _save(figure, output, plt)


def _save(figure, output: Path, plt) -> Path:
    output.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(output, dpi=DPI)
    plt.close(figure)
    return output


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="estimation_plot", description=__doc__.split("\n")[0])
    parser.add_argument("recording", type=Path, help="an MCAP file from estimation_demo --record")
    parser.add_argument("--output", "-o", type=Path, required=True, help="PNG file to write")
    args = parser.parse_args(argv)
    from estimation_nodes.tools.recording.mcap import RecordingError, read_recording

    if args.recording.is_file():
        from estimation_nodes.tools.replay.grid_localizer import recorded_kind

        kind = recorded_kind(args.recording)
        if kind == "grid":
            from estimation_nodes.tools.plot.grid_localizer import render_grid

            print(f"estimation_plot: wrote {render_grid(args.recording, args.output)}")
            return
        if kind == "landmarks":
            from estimation_nodes.tools.plot.landmarks import render_landmarks

            try:
                written = render_landmarks(args.recording, args.output)
            except ValueError as error:
                print(f"estimation_plot: {error}", file=sys.stderr)
                sys.exit(2)
            print(f"estimation_plot: wrote {written}")
            return
    try:
        record = read_recording(args.recording).record
    except RecordingError as error:
        print(f"estimation_plot: {error}", file=sys.stderr)
        sys.exit(2)
    print(f"estimation_plot: wrote {render(record, args.output)}")


if __name__ == "__main__":
    main()
