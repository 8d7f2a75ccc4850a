"""Render a grid localization run as one PNG: the map, the belief and the poses at several updates.

Each panel is one update of the localizer (evenly spread over the run, the
first and the last among them): the map in grey, the belief map (its maximum
over headings) in colour on top, the true path so far (red) and the true and
estimated poses at that update as arrows. Read from a recording of the run
(``estimation_demo --scenario grid_localization --record``). Needs matplotlib.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from estimation_nodes.nodes.grid_messages import planar_pose
from estimation_nodes.params import topics
from estimation_nodes.tools.replay.grid_localizer import header_stamp_ns, recorded_messages

PANELS = 6
#: Width of the picture, and the height of one for a square map (inches at DPI).
FIGURE_INCHES = (16.0, 10.0)
DPI = 100


def _grid(msg) -> tuple[np.ndarray, tuple[float, float, float, float]]:
    """An OccupancyGrid's cells (rows from the origin up) and its extent in m."""
    info, data = msg.info, msg.data
    cells = np.frombuffer(data, dtype=np.int8) if isinstance(data, (bytes, bytearray)) \
        else np.asarray(data, dtype=np.int8)
    cells = cells.reshape(info.height, info.width)
    x0, y0 = info.origin.position.x, info.origin.position.y
    return cells, (x0, x0 + info.width * info.resolution, y0, y0 + info.height * info.resolution)


def render_grid(recording: Path, output: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    messages, _ = recorded_messages(recording)
    maps = [m for t, m in messages if t == f"/{topics.MAP}"]
    if not maps:
        raise ValueError(f"{recording}: no /map message recorded")
    def on(topic: str) -> list:
        return [m for t, m in messages if t == f"/{topic}"]

    stamp = header_stamp_ns
    poses = {stamp(m): planar_pose(m.pose.pose) for m in on(topics.POSE)}
    truths = [(stamp(m), planar_pose(m.pose)) for m in on(topics.TRUE_POSE)]
    truth_at = dict(truths)
    updates = [b for b in on(topics.BELIEF_MAP) if stamp(b) in poses and stamp(b) in truth_at]
    if not updates:
        raise ValueError(f"{recording}: no localizer update with its truth recorded")
    chosen = sorted({int(round(i)) for i in np.linspace(0, len(updates) - 1, PANELS)})
    occupancy, map_extent = _grid(maps[0])
    # Panels shaped like the map: a long corridor two to a row, a square map three.
    aspect = occupancy.shape[0] / occupancy.shape[1]
    cols = 2 if aspect < 0.5 else 3
    rows = math.ceil(PANELS / cols)
    width = FIGURE_INCHES[0]
    height = min(FIGURE_INCHES[1] * 1.5, width / cols * aspect * rows * 1.3 + 1.0)
    figure, axes = plt.subplots(rows, cols, figsize=(width, height), dpi=DPI, squeeze=False)
    for ax, index in zip(axes.ravel(), chosen):
        belief_msg = updates[index]
        at = stamp(belief_msg)
        belief, extent = _grid(belief_msg)
        ax.imshow(np.where(occupancy >= 100, 0.0, np.where(occupancy < 0, 0.6, 1.0)),
                  origin="lower", extent=map_extent, cmap="gray", vmin=0, vmax=1)
        shown = np.ma.masked_less_equal(belief.astype(float), 0)
        ax.imshow(shown, origin="lower", extent=extent, cmap="viridis", alpha=0.8,
                  vmin=0, vmax=100)
        path = np.array([p[:2] for s, p in truths if s <= at])
        if path.size:
            # A kidnapping is a jump, not a path: the line breaks there.
            jumps = np.flatnonzero(np.hypot(*np.diff(path, axis=0).T) > 1.0) + 1
            for number, piece in enumerate(np.split(path, jumps)):
                ax.plot(piece[:, 0], piece[:, 1], color="#d62728", linewidth=1,
                        label="true path" if number == 0 else None)
        for pose, colour, label in ((truth_at[at], "#d62728", "true pose"),
                                    (poses[at], "#1f77b4", "estimate")):
            ax.arrow(pose[0], pose[1], 0.6 * math.cos(pose[2]), 0.6 * math.sin(pose[2]),
                     width=0.08, color=colour, label=label, length_includes_head=True)
        error = math.hypot(poses[at][0] - truth_at[at][0], poses[at][1] - truth_at[at][1])
        ax.set_title(f"update {index + 1} of {len(updates)}: error {error:.2f} m")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
    for ax in axes.ravel()[len(chosen):]:
        ax.axis("off")
    axes.ravel()[0].legend(loc="upper right", fontsize=8)
    figure.suptitle("Grid localization: belief (max over headings), true and estimated pose")
    figure.tight_layout()
    figure.savefig(output)
    plt.close(figure)
    return output
