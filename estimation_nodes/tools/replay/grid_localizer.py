"""estimation_replay for grid localization runs: the localizer offline over the recorded inputs.

The localizer's recorded parameters and its map (its ``map_file``, or the
first recorded ``/map`` when it took the map from the topic) give the same
state grid; odometry and scans are applied in the
order of their header stamps, each scan with the odometry of its time, as
grid_localizer does. The first update is the one the online localizer made
first (it starts from the uniform belief, so what came before it does not
matter). Every online update (a ``pose`` stamped with its scan's time, and
the ``localization_quality`` published just before it) is compared with the
offline one of the same scan: the pose, the (x, y, yaw) covariance and the
quality.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from estimation_nodes.core import errors
from estimation_nodes.nodes.grid_messages import planar_pose
from estimation_nodes.params import topics
from estimation_nodes.params.grid import build_grid_localizer_settings
from estimation_nodes.params.map_files import occupancy_from_message
from estimation_nodes.params.param_files import read_node_parameters
from estimation_nodes.params.scenarios import DEFAULT_KIND, scenario_kind
from estimation_nodes.params.specs import GRID_LOCALIZER_SPECS, spec_defaults
from estimation_nodes.tools.recording.mcap import RecordingError


@dataclass
class GridComparison:
    compared: int = 0
    worst: dict[str, float] = field(default_factory=dict)
    differences: list[str] = field(default_factory=list)

    @property
    def equal(self) -> bool:
        return not self.differences and self.compared > 0


def recorded_kind(path: Path) -> str:
    """The kind of run a recording is, as its scenario said (params/scenarios.py): the
    demo keeps it, and the parameter file, in the recording's metadata."""
    from mcap.reader import make_reader

    from estimation_nodes.tools.recording.mcap import METADATA_NAME

    with path.open("rb") as stream:
        for entry in make_reader(stream).iter_metadata():
            if entry.name == METADATA_NAME:
                metadata = dict(entry.metadata)
                return metadata.get("kind") or scenario_kind(
                    metadata.get("parameters_yaml", ""))
    return DEFAULT_KIND


def is_grid_recording(path: Path) -> bool:
    return recorded_kind(path) == "grid"


def recorded_messages(path: Path) -> tuple[list[tuple[str, object]], dict[str, str]]:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    with path.open("rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        decoded = [(m.publish_time, m.log_time, c.topic, d)
                   for _s, c, m, d in reader.iter_decoded_messages(log_time_order=True)]
        metadata = next((dict(e.metadata) for e in reader.iter_metadata()
                         if e.name == "estimation_nodes"), {})
    decoded.sort(key=lambda item: item[:2])
    return [(topic, message) for _p, _l, topic, message in decoded], metadata


def header_stamp_ns(msg) -> int:
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


def replay_grid(path: Path, parameters_yaml: str | None, tolerance: float) -> GridComparison:
    from estimation_nodes.nodes.grid_messages import finite_pose, scan_beams

    messages, metadata = recorded_messages(path)
    values = spec_defaults(GRID_LOCALIZER_SPECS)
    values.update(read_node_parameters(parameters_yaml if parameters_yaml is not None
                                       else metadata.get("parameters_yaml", ""),
                                       "/grid_localizer"))
    # The map as the localizer had it: its map_file when it had one (an OccupancyGrid's
    # resolution is a float32, so the recorded /map is not quite the file), else /map.
    settings = build_grid_localizer_settings(values)
    if settings.model is not None:
        model = settings.model
    else:
        maps = [m for t, m in messages if t == f"/{topics.MAP}"]
        if not maps:
            raise RecordingError(f"{path}: no /map message recorded")
        info = maps[0].info
        model = settings.model_for(occupancy_from_message(
            info.width, info.height, info.resolution,
            (info.origin.position.x, info.origin.position.y, 0.0), maps[0].data))
    localization = settings.localization(model)
    online, quality = {}, float("nan")
    for topic, msg in messages:
        if topic == f"/{topics.LOCALIZATION_QUALITY}":
            quality = msg.data
        elif topic == f"/{topics.POSE}":
            online[header_stamp_ns(msg)] = (msg, quality)
    inputs = sorted([(header_stamp_ns(m), 0, t, m) for t, m in messages
                     if t == f"/{topics.ODOM}"] +
                    [(header_stamp_ns(m), 1, t, m) for t, m in messages if t == f"/{topics.SCAN}"],
                    key=lambda item: item[:2])
    comparison = GridComparison()
    started = False
    radius, angle = settings.quality_radius, settings.quality_angle
    for stamp, _rank, topic, msg in inputs:
        if topic == f"/{topics.ODOM}":
            pose = planar_pose(msg.pose.pose)
            if finite_pose(pose):             # the node drops the others, as the core would
                localization.on_odometry(pose, stamp)
            continue
        if not started and stamp not in online:
            continue                          # before the localizer's first update
        started = True
        if not localization.due(stamp):
            continue
        ranges, angles, _ = scan_beams(msg, settings.sensor.max_range, settings.max_beams)
        try:
            localization.update(ranges, angles, stamp)
        except errors.EstimationError:        # dropped online too: nothing published
            continue
        _compare(comparison, stamp, online.get(stamp), localization.estimate(radius, angle),
                 tolerance)
    return comparison


def _compare(comparison: GridComparison, stamp: int, online, offline, tolerance: float) -> None:
    comparison.compared += 1
    if online is None:
        comparison.differences.append(f"update at {stamp / 1e9:.3f} s: computed offline, "
                                      f"not published online")
        return
    msg, quality = online
    pose = np.array(planar_pose(msg.pose.pose))
    offline_pose = np.array(offline.pose)
    yaw_error = abs(math.remainder(pose[2] - offline_pose[2], 2 * math.pi))
    covariance = np.array(msg.pose.covariance).reshape(6, 6)[np.ix_((0, 1, 5), (0, 1, 5))]
    errors = {"pose": max(float(np.max(np.abs(pose[:2] - offline_pose[:2]))), yaw_error),
              "covariance": float(np.max(np.abs(covariance - offline.covariance))),
              "quality": abs(quality - offline.quality)}
    for name, error in errors.items():
        comparison.worst[name] = max(comparison.worst.get(name, 0.0), error)
        if not error <= tolerance:
            comparison.differences.append(
                f"update at {stamp / 1e9:.3f} s: {name} |online - offline| = {error:.3g}")
