"""estimation_replay for landmark runs: ekf_localizer's filter offline over the recorded inputs.

ekf_localizer applies its events (odometry twists, camera frames) in the order of
their stamps, an odometry message before a frame of the same stamp
(core/causal_order.py puts a late one in its place), and publishes after each the
pose as of the newest stamp it has seen. So the last pose it published with a stamp
is the filter over every event up to that stamp, once all of them had come: the
replay runs the filter over the recorded events in stamp order, from the recorded
parameters' initial pose, and compares that last pose, and its covariance, with the
offline filter's at the same stamp.

What the replay cannot hold against the node:

- a pose published before an event of an older or equal stamp was (a late event
  the node had not heard yet): provisional, superseded by what came after;
- an earlier pose of a stamp the node published again (a late event of an older
  stamp came, and the node answered it as of its newest stamp);
- an ``initialpose`` restarts the filter at the next event from that pose: the
  events published after it make a run of their own. ``~/reset`` (a service call)
  is not recorded: the poses after one differ, and the replay says so.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from estimation_nodes.core.kalman.landmarks import LandmarkLocalization
from estimation_nodes.nodes.grid_messages import covariance_3x3, planar_pose
from estimation_nodes.nodes.landmark_messages import MalformedCloudError, landmark_points
from estimation_nodes.params import topics
from estimation_nodes.params.landmarks import EkfLocalizerSettings, build_ekf_localizer_settings
from estimation_nodes.params.param_files import read_node_parameters
from estimation_nodes.params.specs import EKF_LOCALIZER_SPECS, spec_defaults
from estimation_nodes.tools.recording.mcap import RecordingError
from estimation_nodes.tools.replay.grid_localizer import (
    Recorded,
    header_stamp_ns,
    recorded_records,
)

ODOM, FRAMES = f"/{topics.ODOM}", f"/{topics.LANDMARK_OBSERVATIONS}"
INITIAL_POSE, POSE = f"/{topics.INITIAL_POSE}", f"/{topics.POSE}"
#: The node's rank of each input at one stamp (nodes/ekf_localizer.py): motion first.
RANKS = {ODOM: 0, FRAMES: 1}


@dataclass
class LandmarkComparison:
    compared: int = 0
    worst: dict[str, float] = field(default_factory=lambda: {"pose": 0.0, "covariance": 0.0})
    differences: list[str] = field(default_factory=list)
    #: Poses not compared: published before a late event, or published again.
    provisional: int = 0
    #: Inputs the node drops (a twist that is not finite, no stamp, a bad cloud).
    dropped: int = 0

    @property
    def equal(self) -> bool:
        return not self.differences and self.compared > 0


@dataclass(frozen=True)
class Event:
    stamp_ns: int
    rank: int
    publish_ns: int
    data: tuple


def is_landmark_recording(path: Path) -> bool:
    from estimation_nodes.tools.replay.grid_localizer import recorded_kind

    return recorded_kind(path) == "landmarks"


def settings_of(parameters_yaml: str) -> EkfLocalizerSettings:
    """The localizer's settings from the recorded (or given) parameter file."""
    given = read_node_parameters(parameters_yaml, "/ekf_localizer")
    return build_ekf_localizer_settings({**spec_defaults(EKF_LOCALIZER_SPECS), **given})


def input_event(record: Recorded) -> Event | None:
    """The event the node makes of a recorded input; None for one it drops."""
    stamp = header_stamp_ns(record.msg)
    if stamp <= 0:
        return None
    if record.topic == ODOM:
        twist = record.msg.twist.twist
        v, w = twist.linear.x, twist.angular.z
        if not (np.isfinite(v) and np.isfinite(w)):
            return None
        return Event(stamp, RANKS[ODOM], record.publish_ns, ("odom", v, w))
    try:
        observations = landmark_points(record.msg)
    except MalformedCloudError:
        return None
    return Event(stamp, RANKS[FRAMES], record.publish_ns, ("frame", observations))


def runs_of(records: list[Recorded]) -> list[tuple[Any, list[Event], list[Recorded]]]:
    """(initialpose message or None, its events, its poses) for each run between restarts,
    by publish order."""
    runs: list[tuple[Any, list[Event], list[Recorded]]] = [(None, [], [])]
    for record in records:
        if record.topic == INITIAL_POSE:
            runs.append((record.msg, [], []))
        elif record.topic in RANKS:
            runs[-1][1].append(input_event(record) or Event(-1, -1, record.publish_ns, ()))
        elif record.topic == POSE:
            runs[-1][2].append(record)
    return runs


def replay_landmarks(path: Path, parameters_yaml: str | None,
                     tolerance: float) -> LandmarkComparison:
    records, metadata = recorded_records(path)
    text = parameters_yaml if parameters_yaml is not None \
        else metadata.get("parameters_yaml", "")
    if not text:
        raise RecordingError(f"{path}: no parameters in the recording; give --params-file")
    settings = settings_of(text)
    comparison = LandmarkComparison()
    for prior, events, poses in runs_of(records):
        comparison.dropped += sum(1 for e in events if e.rank < 0)
        kept = [e for e in events if e.rank >= 0]
        start = (settings.initial_pose, settings.initial_covariance) if prior is None \
            else (np.array(planar_pose(prior.pose.pose)), covariance_3x3(prior.pose.covariance))
        _compare_run(settings, start, kept, poses, tolerance, comparison)
    return comparison


def _compare_run(settings: EkfLocalizerSettings, start: tuple, events: list[Event],
                 poses: list[Recorded], tolerance: float,
                 comparison: LandmarkComparison) -> None:
    final = _final_poses(events, poses, comparison)
    if not final:
        return
    localization = LandmarkLocalization(settings.model, *start)
    ordered = sorted(events, key=lambda e: (e.stamp_ns, e.rank, e.publish_ns))
    index = 0
    for stamp in sorted(final):
        while index < len(ordered) and ordered[index].stamp_ns <= stamp:
            _apply(localization, ordered[index])
            index += 1
        _check(final[stamp], localization, tolerance, comparison)


def _final_poses(events: list[Event], poses: list[Recorded],
                 comparison: LandmarkComparison) -> dict[int, Recorded]:
    """The poses to compare, by stamp: each stamp's last, unless an event of an older or
    equal stamp was published after it."""
    last: dict[int, Recorded] = {}
    for pose in poses:
        stamp = header_stamp_ns(pose.msg)
        if stamp in last:
            comparison.provisional += 1
        last[stamp] = pose
    # The latest publish time among the events of each stamp and older ones.
    latest_by_stamp: dict[int, int] = defaultdict(int)
    for event in events:
        latest_by_stamp[event.stamp_ns] = max(latest_by_stamp[event.stamp_ns], event.publish_ns)
    final = {}
    stamps = sorted(latest_by_stamp)
    running, latest_up_to = 0, {}
    for stamp in stamps:
        running = max(running, latest_by_stamp[stamp])
        latest_up_to[stamp] = running
    for stamp, pose in last.items():
        newest_input = _at_or_before(stamps, latest_up_to, stamp)
        if newest_input > pose.publish_ns:
            comparison.provisional += 1
        else:
            final[stamp] = pose
    return final


def _at_or_before(stamps: list[int], latest_up_to: dict[int, int], stamp: int) -> int:
    from bisect import bisect_right

    index = bisect_right(stamps, stamp)
    return latest_up_to[stamps[index - 1]] if index else 0


def _apply(localization: LandmarkLocalization, event: Event) -> None:
    t = event.stamp_ns / 1e9
    if event.data[0] == "odom":
        localization.on_odometry(t, event.data[1], event.data[2])
    else:
        localization.on_frame(t, event.data[1])


def _check(pose: Recorded, localization: LandmarkLocalization, tolerance: float,
           comparison: LandmarkComparison) -> None:
    online = np.array(planar_pose(pose.msg.pose.pose))
    offline = localization.pose
    difference = np.abs(online - offline)
    difference[2] = abs((online[2] - offline[2] + np.pi) % (2 * np.pi) - np.pi)
    pose_difference = float(difference.max())
    covariance_difference = float(np.abs(covariance_3x3(pose.msg.pose.covariance)
                                         - localization.pose_covariance).max())
    comparison.compared += 1
    worst = comparison.worst
    worst["pose"] = max(worst["pose"], pose_difference)
    worst["covariance"] = max(worst["covariance"], covariance_difference)
    if max(pose_difference, covariance_difference) > tolerance:
        stamp = header_stamp_ns(pose.msg) / 1e9
        comparison.differences.append(
            f"  pose at {stamp:.6f} s: online {np.round(online, 6).tolist()}, offline "
            f"{np.round(offline, 6).tolist()} (pose {pose_difference:.3g}, covariance "
            f"{covariance_difference:.3g})")
