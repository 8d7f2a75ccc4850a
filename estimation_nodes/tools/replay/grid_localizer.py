"""estimation_replay for grid localization runs: the localizer offline over the recorded inputs.

What the online localizer did is read from what it published, in the order
it published it (each message's publish time, DDS's source timestamp). Each
``pose`` carries the stamp of what made it, so:

- a pose stamped with a recorded scan's time is an update with that scan.
  The replay takes exactly the scans the localizer took, whatever it left out
  (a scan superseded while it waited for the odometry of its time, one whose
  odometry never came, one it had no time for), and checks that its update
  rule takes each of them;
- a pose stamped with a recorded ``initialpose``'s time is that prior; an
  initial pose sent without a stamp (``ros2 topic pub /initialpose`` as typed,
  or a tool that leaves it 0) is answered with a pose stamped at the
  localizer's clock, so such a prior is the first pose published after it that
  no scan or stamped prior explains;
- any other pose is a reset to the uniform belief: the start on a map (from
  map_file, or a /map message published since the localizer's last output)
  or ``~/global_localization`` (a service call, which is not recorded).

Odometry is applied in the order of its stamps, each update predicting with
the odometry at or before its scan's time, as grid_localizer does; the
localizer's recorded parameters and its map (its ``map_file``, or the /map
message it started on) give the same state grid. Each update's pose, (x, y,
yaw) covariance and ``localization_quality`` (the one published just before
its pose) are compared with the offline ones. A pose none of this explains
(its scan is missing from the recording: a recorder that heard the sensor
after the localizer did) stops the comparison there, since every later
update depends on it.
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from estimation_nodes.core import errors
from estimation_nodes.core.grid.localization import Estimate, GridLocalization
from estimation_nodes.core.transforms.buffer import LookupFailed, TransformBuffer
from estimation_nodes.core.validation import check_covariance
from estimation_nodes.nodes.grid_messages import (
    covariance_3x3,
    finite_pose,
    occupancy_of,
    planar_pose,
    scan_beams,
)
from estimation_nodes.params import topics
from estimation_nodes.nodes.tf import from_message
from estimation_nodes.params.grid import (GridFrames, GridLocalizerSettings,
                                          build_grid_localizer_settings)
from estimation_nodes.params.param_files import read_node_parameters
from estimation_nodes.params.scenarios import DEFAULT_KIND, scenario_kind
from estimation_nodes.params.specs import GRID_LOCALIZER_SPECS, spec_defaults
from estimation_nodes.params.wording import plural
from estimation_nodes.tools.recording.mcap import RecordingError

MAP, SCAN, ODOM = f"/{topics.MAP}", f"/{topics.SCAN}", f"/{topics.ODOM}"
TF, TF_STATIC = "/tf", "/tf_static"
INITIAL_POSE, POSE = f"/{topics.INITIAL_POSE}", f"/{topics.POSE}"
QUALITY = f"/{topics.LOCALIZATION_QUALITY}"


@dataclass(frozen=True)
class Recorded:
    """One recorded message: its topic, when it was published (ns), the message."""

    topic: str
    publish_ns: int
    msg: Any


@dataclass(frozen=True)
class Step:
    """One output of the online localizer and what made it.

    ``kind``: "update" (``scan`` is the scan it took), "prior" (``prior`` is the
    initialpose message), "start" (on the map of ``maps``, the last one that makes a
    state grid; empty when the map is the map_file) or "reset" (global localization).
    ``quality``: the localization_quality published just before ``pose`` (None: not
    recorded).
    """

    kind: str
    pose: Any
    quality: float | None
    scan: Any = None
    prior: Any = None
    maps: tuple = ()

    @property
    def stamp_ns(self) -> int:
        return header_stamp_ns(self.pose)


@dataclass
class GridComparison:
    compared: int = 0
    worst: dict[str, float] = field(default_factory=dict)
    differences: list[str] = field(default_factory=list)
    #: Outputs that were not updates: starts, resets (global localization), priors.
    others: dict[str, int] = field(default_factory=lambda: defaultdict(int))
    #: Scans the update rule would have taken that the localizer left out.
    left_out: int = 0
    #: Updates taken to have been made before the first recorded output (0: none).
    assumed: int = 0

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


def recorded_records(path: Path) -> tuple[list[Recorded], dict[str, str]]:
    """Every recorded message in the order it was published, and the recording's metadata."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    with path.open("rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        decoded = [(m.publish_time, m.log_time, c.topic, d)
                   for _s, c, m, d in reader.iter_decoded_messages(log_time_order=True)]
        metadata = next((dict(e.metadata) for e in reader.iter_metadata()
                         if e.name == "estimation_nodes"), {})
    decoded.sort(key=lambda item: item[:2])
    return [Recorded(topic, published, msg) for published, _l, topic, msg in decoded], metadata


def recorded_messages(path: Path) -> tuple[list[tuple[str, object]], dict[str, str]]:
    """(topic, message) of every recorded message in the order it was published."""
    records, metadata = recorded_records(path)
    return [(r.topic, r.msg) for r in records], metadata


def header_stamp_ns(msg) -> int:
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


def localizer_steps(records: list[Recorded], map_from_topic: bool) -> list[Step]:
    """What the online localizer did, output by output, read from its outputs' stamps.

    ``records`` in the order they were published. A pose is an update when its stamp
    is a recorded scan's, a prior when it is a recorded initial pose's (or the first
    pose after an unstamped one: the localizer stamps its answer with its own clock),
    else a reset: a start when it is the localizer's first output or, with
    ``map_from_topic``, when a /map was published since its last one.
    """
    scans: dict[int, list] = defaultdict(list)
    priors: dict[int, list] = defaultdict(list)
    for record in records:
        if record.topic == SCAN:
            scans[header_stamp_ns(record.msg)].append(record.msg)
        elif record.topic == INITIAL_POSE and header_stamp_ns(record.msg):
            priors[header_stamp_ns(record.msg)].append(record.msg)
    steps: list[Step] = []
    quality: float | None = None
    maps_since: list = []
    unstamped_priors: list = []          # sent, not answered yet, in the order sent
    for record in records:
        if record.topic == MAP:
            maps_since.append(record.msg)
        elif record.topic == INITIAL_POSE and not header_stamp_ns(record.msg):
            if _acceptable_prior(record.msg):
                unstamped_priors.append(record.msg)
        elif record.topic == QUALITY:
            quality = record.msg.data
        elif record.topic == POSE:
            stamp = header_stamp_ns(record.msg)
            if scans.get(stamp):
                steps.append(Step("update", record.msg, quality, scan=scans[stamp].pop(0)))
            elif priors.get(stamp):
                steps.append(Step("prior", record.msg, quality, prior=priors[stamp].pop(0)))
            elif unstamped_priors and steps:
                steps.append(Step("prior", record.msg, quality, prior=unstamped_priors.pop(0)))
            elif not steps or (map_from_topic and maps_since):
                steps.append(Step("start", record.msg, quality,
                                  maps=tuple(maps_since) if map_from_topic else ()))
            else:
                steps.append(Step("reset", record.msg, quality))
            if steps[-1].kind == "start":
                maps_since = []
            quality = None
    return steps


def _acceptable_prior(msg) -> bool:
    """Whether the localizer answers this initial pose (it drops one that is not
    finite, or whose covariance is not one: see GridLocalizer._on_initial_pose)."""
    pose, covariance = planar_pose(msg.pose.pose), covariance_3x3(msg.pose.covariance)
    if not (finite_pose(pose) and np.isfinite(covariance).all()):
        return False
    try:
        check_covariance("covariance", covariance, 3)
    except errors.EstimationError:
        return False
    return True


def replay_grid(path: Path, parameters_yaml: str | None, tolerance: float) -> GridComparison:
    """The localizer offline over the recording at ``path``, compared with what it
    published; its parameters from ``parameters_yaml`` or else the recording's."""
    records, metadata = recorded_records(path)
    values = spec_defaults(GRID_LOCALIZER_SPECS)
    given = read_node_parameters(parameters_yaml if parameters_yaml is not None
                                 else metadata.get("parameters_yaml", ""), "/grid_localizer")
    # A run recorded before odometry could come from tf took it from the odom topic.
    values.update({"odometry_source": "topic", **given})
    try:
        return replay_records(records, values, tolerance)
    except errors.MapError as error:
        raise RecordingError(f"{path}: {error}") from None


def replay_records(records: list[Recorded], values: dict, tolerance: float) -> GridComparison:
    """Replay ``records`` (in the order they were published) with the localizer's
    parameter ``values``; every output compared (see the module's docstring)."""
    settings = build_grid_localizer_settings(values)
    steps = localizer_steps(records, map_from_topic=settings.model is None)
    inputs = _InputsInStampOrder(records, settings.frames)
    comparison = GridComparison()
    localization: GridLocalization | None = None

    def update(scan, stamp_ns: int) -> None:
        ranges, angles, _ = scan_beams(scan, settings.sensor.max_range, settings.max_beams)
        assert localization is not None
        localization.update(ranges, angles, stamp_ns,
                            inputs.odometry_of(scan, stamp_ns, localization))

    for step in steps:
        assumed = None
        alone = GridComparison()                 # this step's differences
        if step.kind == "start":
            localization = settings.localization(_model(settings, step.maps, records))
        elif localization is None:
            # The recorder heard the localizer after it started: of what it published
            # before, it got the latest output only (latched). Take it to have started
            # before the first recorded scan and to have taken every scan its rule takes
            # until this output, which then says whether it did.
            localization = settings.localization(_model(settings, (), records))
            assumed = inputs.advance_to(step.stamp_ns, localization, take=update)
        try:
            if step.kind == "reset":
                localization.global_localization()
            elif step.kind == "prior":
                localization.set_prior(planar_pose(step.prior.pose.pose),
                                       covariance_3x3(step.prior.pose.covariance))
            elif step.kind == "update":
                if assumed is None:
                    comparison.left_out += inputs.advance_to(step.stamp_ns, localization)
                if not localization.due(step.stamp_ns, inputs.odometry_of(
                        step.scan, step.stamp_ns, localization)):
                    alone.differences.append(
                        f"{_at(step)}: the localizer updated with this scan, which its "
                        f"update rule does not take (is odometry of its time missing?)")
                update(step.scan, step.stamp_ns)
        except (ValueError, errors.ZeroEvidenceError) as error:
            comparison.differences.append(f"{_at(step)}: offline, this failed: {error}")
            break
        offline = localization.estimate(settings.quality_radius, settings.quality_angle)
        if step.kind == "update":
            comparison.compared += 1
        else:
            comparison.others[step.kind] += 1
        _compare(alone, step, offline, tolerance)
        if alone.differences and assumed is not None:
            comparison.differences.append(
                f"{_at(step)}: the first output recorded; what the localizer published "
                f"before it was not (a recorder that heard it late), and the update rule "
                f"over the {plural(assumed, 'recorded scan')} it takes before this does not "
                f"make it: the localizer left some out, so nothing after can be compared")
            break
        if alone.differences and step.kind == "reset":
            comparison.others[step.kind] -= 1
            comparison.differences.append(
                f"pose at {step.stamp_ns / 1e9:.3f} s: not of a recorded scan or initial "
                f"pose, nor the uniform belief of a reset: what made it is not in the "
                f"recording (a recorder that heard the sensor after the localizer did?); "
                f"every later update depends on it, so the comparison stops here")
            break
        comparison.differences += alone.differences
        for name, error in alone.worst.items():
            comparison.worst[name] = max(comparison.worst.get(name, 0.0), error)
        if assumed:
            comparison.assumed = assumed
    return comparison


class _InputsInStampOrder:
    """The recorded odometry and scans by their stamps, fed to the offline localizer up to
    each scan it updates with. With odometry from tf, the odometry is every recorded
    odom -> base_link sample the node's buffer takes, and each scan's own odometry and
    mount are the recorded tree's at its time, as the node takes them."""

    def __init__(self, records: list[Recorded], frames: GridFrames) -> None:
        self._frames = frames
        if frames.odometry_from_tf:
            self._tree, samples = _recorded_tree(records, frames)
            events = [(stamp, 0, pose) for stamp, pose in samples]
        else:
            self._tree = None
            events = [(header_stamp_ns(r.msg), 0, r.msg) for r in records if r.topic == ODOM]
        events += [(header_stamp_ns(r.msg), 1, r.msg) for r in records if r.topic == SCAN]
        events.sort(key=lambda event: event[:2])
        self._events = events
        self._next = 0

    def advance_to(self, stamp_ns: int, localization: GridLocalization,
                   take: Callable[[Any, int], None] | None = None) -> int:
        """Apply the odometry up to ``stamp_ns`` (a scan's, or a reset's time), as the
        localizer follows it; the scans before it that the update rule takes: how many
        (left out online, as the localizer took the next one), or with ``take`` taken."""
        due = 0
        events = self._events
        while self._next < len(events) and events[self._next][:2] <= (stamp_ns, 0):
            stamp, rank, msg = events[self._next]
            self._next += 1
            if rank == 0:
                pose = msg if isinstance(msg, tuple) else planar_pose(msg.pose.pose)
                if finite_pose(pose):             # the localizer drops the others
                    localization.on_odometry(pose, stamp or None)
            # Before the first update the localizer may not have been there yet.
            elif (take is not None or localization.updates) \
                    and localization.due(stamp, self.odometry_of(msg, stamp, localization)):
                due += 1
                if take is not None:
                    take(msg, stamp)
        # The scan of this update comes next: step over it.
        while self._next < len(events) and events[self._next][:2] == (stamp_ns, 1):
            self._next += 1
        return due

    def odometry_of(self, scan: Any, stamp: int, localization: GridLocalization
                    ) -> tuple[float, float, float] | None:
        """With odometry from tf, the tree's at the scan's time (its mount taken); None
        otherwise, or where the tree cannot say (the localizer dropped that scan)."""
        if self._tree is None:
            return None
        frames = self._frames
        frame = scan.header.frame_id
        try:
            odom_base = self._tree.lookup(frames.odom_frame_id, frames.base_frame_id, stamp)
            mount = frames.laser_pose or (
                (0.0, 0.0, 0.0) if frame in ("", frames.base_frame_id)
                else self._tree.lookup(frames.base_frame_id, frame, stamp).as_planar())
        except LookupFailed:
            return None
        localization.set_laser_pose(mount)
        return odom_base.as_planar()


def _recorded_tree(records: list[Recorded], frames: GridFrames
                   ) -> tuple[TransformBuffer, list[tuple[int, tuple[float, float, float]]]]:
    """Every recorded /tf and /tf_static transform, kept for the whole run (those the
    localizer's buffer refuses refused here too), and the odom -> base_link samples taken,
    in order."""
    tree = TransformBuffer(cache_time_ns=1 << 62)
    samples = []
    for record in records:
        if record.topic not in (TF, TF_STATIC):
            continue
        for transform in record.msg.transforms:
            try:
                parent, child, stamp, taken = from_message(transform)
                tree.set_transform(parent, child, stamp, taken,
                                   static=record.topic == TF_STATIC)
            except errors.EstimationError:
                continue
            if (parent, child) == (frames.odom_frame_id, frames.base_frame_id):
                samples.append((stamp, taken.as_planar()))
    return tree, samples


def _model(settings: GridLocalizerSettings, maps: tuple, records: list[Recorded]):
    """The state grid the localizer started on: its map_file's, else that of the last map
    published before its start that makes one (an OccupancyGrid's resolution is a float32,
    so a recorded /map is not quite the file)."""
    if settings.model is not None:
        return settings.model
    candidates = list(maps) or [r.msg for r in records if r.topic == MAP][:1]
    if not candidates:
        raise RecordingError("no /map message recorded")
    error: errors.MapError | None = None
    for msg in reversed(candidates):
        try:
            return settings.model_for(occupancy_of(msg))
        except errors.MapError as refused:   # the localizer dropped it too
            error = refused
    assert error is not None
    raise error


def _at(step: Step) -> str:
    what = {"update": "update", "prior": "initial pose", "start": "start",
            "reset": "reset"}[step.kind]
    return f"{what} at {step.stamp_ns / 1e9:.3f} s"


def _compare(comparison: GridComparison, step: Step, offline: Estimate,
             tolerance: float) -> None:
    msg = step.pose
    pose = np.array(planar_pose(msg.pose.pose))
    offline_pose = np.array(offline.pose)
    yaw_error = abs(math.remainder(pose[2] - offline_pose[2], 2 * math.pi))
    covariance = covariance_3x3(msg.pose.covariance)
    differences = {
        "pose": max(float(np.max(np.abs(pose[:2] - offline_pose[:2]))), yaw_error),
        "covariance": float(np.max(np.abs(covariance - offline.covariance)))}
    if step.quality is None:
        comparison.differences.append(f"{_at(step)}: its localization_quality is not in the "
                                      f"recording")
    else:
        differences["quality"] = abs(step.quality - offline.quality)
    for name, error in differences.items():
        comparison.worst[name] = max(comparison.worst.get(name, 0.0), error)
        if not error <= tolerance:
            comparison.differences.append(
                f"{_at(step)}: {name} |online - offline| = {error:.3g}")
