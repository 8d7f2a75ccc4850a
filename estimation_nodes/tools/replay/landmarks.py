"""estimation_replay for landmark runs: ekf_localizer's filter offline over the recorded inputs.

ekf_localizer applies its events (odometry twists, camera frames) in the order of
their stamps, an odometry message before a frame of the same stamp
(core/causal_order.py puts a late one in its place), and publishes one pose after
each event it takes, stamped with the newest stamp it has seen. The replay runs the
filter over the recorded events in stamp order, from the recorded parameters'
initial pose, and compares each pose the node published, and its covariance, with
the offline filter's at the pose's stamp, where it can tell that the node had taken
every event up to that stamp by then:

- the node's k-th pose came after exactly k events, and each topic's events are
  taken in the order they were published. So of the odometry, at least k minus
  the frames published before the pose had been taken, and of the frames, at
  least k minus the odometry published before it. A pose is compared when those
  include every event of its stamp or older; any other is provisional (a late
  event, or one still queued on the other topic), counted and not compared. A
  pose the recorder missed only makes these bounds looser;
- an event that came more than ``reorder_horizon`` behind the newest (the node
  applies it late, out of order; with a horizon of 0, any out-of-order event)
  ends the comparison: the poses after it are counted, not compared;
- an ``initialpose`` the node takes (finite, its covariance positive definite)
  restarts the filter from that pose at the next event: the events and poses
  published after it make a run of their own (a pose of the old run published
  after the initialpose was sent would be taken for the new run's). ``~/reset`` (a
  service call) is not recorded: the poses after one differ, and the replay says
  so.
"""

from __future__ import annotations

from bisect import bisect_left, bisect_right
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from estimation_nodes.core.kalman.landmarks import LandmarkLocalization
from estimation_nodes.nodes.grid_messages import covariance_3x3, planar_pose
from estimation_nodes.nodes.landmark_messages import (
    MalformedCloudError,
    initial_pose_of,
    landmark_points,
)
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
    #: Poses not compared: an event of their stamp or older may not have been taken yet.
    provisional: int = 0
    #: Poses not compared: published after an event later than reorder_horizon.
    after_too_late: int = 0
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
    if stamp == 0:                          # unstamped: the node drops it
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
    """((pose, covariance) of the initialpose that began it, or None, its events, its poses)
    for each run between restarts, by publish order; an initialpose the node refuses
    begins none."""
    runs: list[tuple[Any, list[Event], list[Recorded]]] = [(None, [], [])]
    for record in records:
        if record.topic == INITIAL_POSE:
            try:
                runs.append((initial_pose_of(record.msg), [], []))
            except ValueError:
                pass
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
            else prior
        _compare_run(settings, start, kept, poses, tolerance, comparison)
        if comparison.after_too_late:
            break                             # the node's state from there on is not known
    return comparison


def _compare_run(settings: EkfLocalizerSettings, start: tuple, events: list[Event],
                 poses: list[Recorded], tolerance: float,
                 comparison: LandmarkComparison) -> None:
    poses = _before_too_late(events, poses, settings.reorder_horizon, comparison)
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


def _before_too_late(events: list[Event], poses: list[Recorded], horizon_s: float,
                     comparison: LandmarkComparison) -> list[Recorded]:
    """The poses published before the first event that came more than the horizon behind
    the newest (by publish order); the others are counted."""
    newest, horizon_ns = None, int(horizon_s * 1e9)
    for event in sorted(events, key=lambda e: e.publish_ns):
        if newest is not None and event.stamp_ns < newest - horizon_ns:
            kept = [pose for pose in poses if pose.publish_ns < event.publish_ns]
            comparison.after_too_late += len(poses) - len(kept)
            return kept
        newest = event.stamp_ns if newest is None else max(newest, event.stamp_ns)
    return poses


def _final_poses(events: list[Event], poses: list[Recorded],
                 comparison: LandmarkComparison) -> dict[int, Recorded]:
    """The poses that had every event of their stamp or older in them, by stamp (the last
    such one of a stamp); the others are counted as provisional."""
    by_topic = {rank: sorted((e for e in events if e.rank == rank), key=lambda e: e.publish_ns)
                for rank in RANKS.values()}
    published = {rank: [e.publish_ns for e in topic_events]
                 for rank, topic_events in by_topic.items()}
    needed = {rank: _NeededCount(topic_events) for rank, topic_events in by_topic.items()}
    final: dict[int, Recorded] = {}
    for k, pose in enumerate(sorted(poses, key=lambda p: p.publish_ns), start=1):
        stamp = header_stamp_ns(pose.msg)
        before = {rank: bisect_left(times, pose.publish_ns) for rank, times in published.items()}
        taken_at_least = {rank: k - sum(n for other, n in before.items() if other != rank)
                          for rank in before}
        if all(taken_at_least[rank] >= needed[rank].up_to(stamp) for rank in by_topic):
            final[stamp] = pose
        else:
            comparison.provisional += 1
    return final


class _NeededCount:
    """How many of a topic's events (in publish order) must have been taken for all of its
    events up to a stamp to be in: the position of the last such one."""

    def __init__(self, topic_events: list[Event]) -> None:
        ordered = sorted((e.stamp_ns, position)
                         for position, e in enumerate(topic_events, start=1))
        self._stamps = [stamp for stamp, _ in ordered]
        self._last_position = list(np.maximum.accumulate([p for _, p in ordered] or [0]))

    def up_to(self, stamp: int) -> int:
        index = bisect_right(self._stamps, stamp)
        return int(self._last_position[index - 1]) if index else 0


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
