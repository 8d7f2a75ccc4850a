"""Render a landmark localization run as one PNG: the track among the landmarks, and the
error against the filter's own bound.

Left: the landmarks (with their ids), the true path (red), the estimated track (blue)
and the estimate's 95% position ellipse every ELLIPSE_EVERY_S seconds. Right: the
position error over time beside the bound the covariance claims (the 95% ellipse's
longest radius: the error should lie under it at least 95% of the time). Read from a
recording of the run (``estimation_demo --scenario landmarks --record``); the landmarks
from the file the localizer read (the recording keeps its parameters). Needs matplotlib.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from estimation_nodes.nodes.grid_messages import planar_pose
from estimation_nodes.params import topics
from estimation_nodes.tools.replay.grid_localizer import header_stamp_ns, recorded_messages

ELLIPSE_EVERY_S = 5.0
#: The chi-square (2 degrees of freedom) 0.95 quantile: the 95% ellipse's squared radius.
CHI2_95 = -2.0 * math.log(0.05)
FIGURE_INCHES = (15.0, 6.5)
DPI = 100


def _track(messages: list, topic: str) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """Stamps (s), poses (x, y, yaw) and, for a pose with covariance, the x-y blocks."""
    stamps, poses, blocks = [], [], []
    for name, msg in messages:
        if name != f"/{topic}":
            continue
        stamps.append(header_stamp_ns(msg) / 1e9)
        pose = getattr(msg.pose, "pose", msg.pose)
        poses.append(planar_pose(pose))
        if hasattr(msg.pose, "covariance"):
            blocks.append(np.array(msg.pose.covariance).reshape(6, 6)[:2, :2])
    order = np.argsort(stamps, kind="stable")
    return np.array(stamps)[order], np.array(poses).reshape(-1, 3)[order], \
        [blocks[i] for i in order] if blocks else []


def _ellipse(center: np.ndarray, block: np.ndarray) -> np.ndarray:
    """Points of the 95% ellipse of a 2 x 2 covariance around ``center``."""
    values, vectors = np.linalg.eigh(0.5 * (block + block.T))
    radii = np.sqrt(np.maximum(values, 0.0) * CHI2_95)
    angles = np.linspace(0.0, 2 * math.pi, 48)
    circle = np.stack([np.cos(angles), np.sin(angles)])
    return (vectors @ (radii[:, None] * circle)).T + center


def recorded_landmarks(metadata: Mapping[str, str]) -> dict[int, tuple[float, float]]:
    """The landmarks of the file the recorded run's localizer read."""
    from estimation_nodes.params.landmarks import read_landmarks_file
    from estimation_nodes.params.param_files import read_node_parameters

    values = read_node_parameters(metadata.get("parameters_yaml", ""), "/ekf_localizer")
    return read_landmarks_file(str(values.get("landmarks_file", "")))


def render_landmarks(recording: Path, output: Path,
                     landmarks: Mapping[int, tuple[float, float]] | None = None) -> Path:
    """The picture; ``landmarks`` None: those the recorded run's localizer read."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    messages, metadata = recorded_messages(recording)
    if landmarks is None:
        landmarks = recorded_landmarks(metadata)
    times, estimates, blocks = _track(messages, topics.POSE)
    truth_times, truths, _ = _track(messages, topics.TRUE_POSE)
    if not len(times) or not len(truth_times):
        raise ValueError(f"{recording}: no estimate with its truth recorded")
    figure, (track, errors) = plt.subplots(1, 2, figsize=FIGURE_INCHES, dpi=DPI,
                                           gridspec_kw={"width_ratios": [1.2, 1]})
    where = np.array(list(landmarks.values()))
    track.scatter(where[:, 0], where[:, 1], marker="^", color="black", label="landmarks")
    for key, (x, y) in landmarks.items():
        track.annotate(str(key), (x, y), textcoords="offset points", xytext=(4, 4),
                       fontsize=7)
    track.plot(truths[:, 0], truths[:, 1], color="#d62728", linewidth=1, label="true path")
    track.plot(estimates[:, 0], estimates[:, 1], color="#1f77b4", linewidth=1,
               label="estimate")
    shown_at = -math.inf
    for t, pose, block in zip(times, estimates, blocks):
        if t - shown_at >= ELLIPSE_EVERY_S:
            outline = _ellipse(pose[:2], block)
            track.plot(outline[:, 0], outline[:, 1], color="#1f77b4", linewidth=0.6,
                       alpha=0.7, label="95% ellipse" if shown_at == -math.inf else None)
            shown_at = t
    track.set_aspect("equal")
    track.set_xlabel("x (m)")
    track.set_ylabel("y (m)")
    track.legend(loc="best", fontsize=8)
    # the estimate in force at each true pose's time, against it
    index = np.searchsorted(times, truth_times, side="right") - 1
    scored = index >= 0
    distance = np.hypot(*(estimates[index[scored], :2] - truths[scored, :2]).T)
    bound = np.array([math.sqrt(CHI2_95 * float(np.linalg.eigvalsh(blocks[i]).max()))
                      for i in index[scored]]) if blocks else np.full(distance.size, np.nan)
    elapsed = truth_times[scored] - truth_times[0]
    errors.plot(elapsed, distance, color="#1f77b4", linewidth=1, label="position error")
    errors.plot(elapsed, bound, color="grey", linewidth=1, linestyle="--",
                label="95% bound (the covariance's)")
    errors.set_xlabel("time (s)")
    errors.set_ylabel("m")
    errors.legend(loc="upper right", fontsize=8)
    errors.set_title(f"position RMSE {math.sqrt(float(np.mean(distance ** 2))):.3f} m")
    figure.suptitle("Landmark localization: the track, the truth and the 95% ellipses")
    figure.tight_layout()
    figure.savefig(output)
    plt.close(figure)
    return output
