"""The grid replay takes exactly the scans the localizer took, read from its poses' stamps.

The localizer may leave a scan out (superseded while it waited for its
odometry, dropped when that never came, or one it had no time for); its
update rule then runs from another reference, so a replay that applied the
rule to every recorded scan computed updates the localizer never made and
differed from the first skipped scan on (issue 24: 56 and 33 differences).
"""

import math

import numpy as np
import pytest
from geometry_msgs.msg import PoseWithCovarianceStamped
from nav_msgs.msg import OccupancyGrid, Odometry
from sensor_msgs.msg import LaserScan
from std_msgs.msg import Float64

from estimation_nodes.core.sim import planar
from estimation_nodes.nodes.grid_messages import fill_pose, pose_with_covariance, scan_beams
from estimation_nodes.params.grid import build_grid_localizer_settings
from estimation_nodes.params.map_files import read_map_file
from estimation_nodes.params.specs import GRID_LOCALIZER_SPECS, spec_defaults
from estimation_nodes.tools.replay.grid_localizer import (
    Recorded,
    localizer_steps,
    replay_records,
)
from tests.conftest import REPO

CORRIDOR = REPO / "maps" / "corridor.yaml"
SECOND = 10**9
T0 = 1000 * SECOND


def stamped(msg, stamp_ns: int):
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, SECOND)
    return msg


def odom(pose, stamp_ns):
    msg = stamped(Odometry(), stamp_ns)
    fill_pose(msg.pose.pose, *pose)
    return msg


def scan(ranges, angles, stamp_ns):
    msg = stamped(LaserScan(), stamp_ns)
    msg.angle_min, msg.angle_increment = float(angles[0]), float(angles[1] - angles[0])
    msg.range_min, msg.range_max = 0.05, 12.0
    msg.ranges = [float(r) for r in ranges]
    return msg


def initial_pose(pose, stamp_ns):
    msg = stamped(PoseWithCovarianceStamped(), stamp_ns)
    cov = np.diag([0.04, 0.04, 0.0, 0.0, 0.0, 0.01])
    return pose_with_covariance(msg, pose, cov[np.ix_((0, 1, 5), (0, 1, 5))])


def stamp_of(step: int) -> int:
    return T0 + step * SECOND // 10


class Run:
    """A recording made by hand: the inputs, and what a localizer that took only some
    scans published, each message with its publish time."""

    def __init__(self) -> None:
        self.values = spec_defaults(GRID_LOCALIZER_SPECS)
        self.values.update(map_file=str(CORRIDOR), heading_bins=8, odometry_source="topic")
        self.settings = build_grid_localizer_settings(self.values)
        self.localization = self.settings.localization(self.settings.model)
        self.records: list[Recorded] = []
        self._clock = T0

    def record(self, topic: str, msg) -> None:
        self._clock += 1000
        self.records.append(Recorded(topic, self._clock, msg))

    def publish_estimate(self, stamp_ns: int) -> None:
        """As grid_localizer publishes after each change of its belief: quality, pose."""
        estimate = self.localization.estimate(self.settings.quality_radius,
                                              self.settings.quality_angle)
        self.record("/localization_quality", Float64(data=estimate.quality))
        pose = pose_with_covariance(stamped(PoseWithCovarianceStamped(), stamp_ns),
                                    estimate.pose, estimate.covariance)
        self.record("/pose", pose)


def a_run_that_leaves_scans_out(left_out=(3, 4, 9), reset_at=6, prior_at=11):
    """The robot drives along the corridor, a step of 0.15 m per scan (a scan is due
    after 0.25 m): the localizer takes the due ones except ``left_out``, is reset at
    step ``reset_at`` and given an initial pose at ``prior_at``."""
    run = Run()
    world = planar.planar_world(read_map_file(CORRIDOR))
    angles = -math.pi + 2 * math.pi * np.arange(90) / 90
    run.publish_estimate(T0 - SECOND)                   # the start: stamped "now"
    taken = []
    for step in range(16):
        stamp = stamp_of(step)
        pose = (3.0 + 0.15 * step, 2.0, 0.02 * step)
        run.record("/odom", odom(pose, stamp))
        run.localization.on_odometry(pose, stamp)
        msg = scan(planar.ray_cast(world, pose, angles, 12.0), angles, stamp)
        run.record("/scan", msg)
        if step == reset_at:
            run.localization.global_localization()
            run.publish_estimate(stamp + 5000)
        if step == prior_at:
            prior = initial_pose((pose[0], pose[1], pose[2]), stamp + 7000)
            run.record("/initialpose", prior)
            run.localization.set_prior(pose, np.diag([0.04, 0.04, 0.01]))
            run.publish_estimate(stamp + 7000)
        if step not in left_out and run.localization.due(stamp):
            ranges, beam_angles, _ = scan_beams(msg, run.settings.sensor.max_range,
                                                run.settings.max_beams)
            run.localization.update(ranges, beam_angles, stamp)
            run.publish_estimate(stamp)
            taken.append(stamp)
    return run, taken


def test_the_steps_are_read_from_the_poses_stamps():
    run, taken = a_run_that_leaves_scans_out()
    steps = localizer_steps(run.records, map_from_topic=False)
    kinds = [step.kind for step in steps]
    assert kinds[0] == "start" and kinds.count("reset") == 1 and kinds.count("prior") == 1
    assert [s.stamp_ns for s in steps if s.kind == "update"] == taken
    poses = [i for i, r in enumerate(run.records) if r.topic == "/pose"]
    assert [s.pose for s in steps] == [run.records[i].msg for i in poses]
    # Each output's quality is the one published just before its pose.
    assert [s.quality for s in steps] == [run.records[i - 1].msg.data for i in poses]


def test_a_map_from_the_topic_starts_the_localizer_again():
    """A new /map since the localizer's last output: its next non-update pose is a start
    on that map, not a reset (when the localizer takes the map from the topic)."""
    run, _ = a_run_that_leaves_scans_out()
    reset = next(r for r in localizer_steps(run.records, False) if r.kind == "reset")
    at = next(i for i, r in enumerate(run.records) if r.msg is reset.pose)
    records = [Recorded("/map", T0 - 2 * SECOND, OccupancyGrid())] + run.records
    records.insert(at, Recorded("/map", records[at].publish_ns - 1, OccupancyGrid()))
    from_topic = localizer_steps(records, map_from_topic=True)
    assert [s.kind for s in from_topic].count("start") == 2
    assert len(from_topic[0].maps) == 1 and "reset" not in [s.kind for s in from_topic]
    from_file = localizer_steps(records, map_from_topic=False)
    assert [s.kind for s in from_file].count("start") == 1


def test_a_run_whose_localizer_left_scans_out_replays_equal():
    run, taken = a_run_that_leaves_scans_out()
    comparison = replay_records(run.records, run.values, 1e-9)
    assert comparison.differences == [] and comparison.equal
    assert comparison.compared == len(taken) >= 5
    assert dict(comparison.others) == {"start": 1, "reset": 1, "prior": 1}
    # Scans the update rule takes were left out: taking every due scan would differ.
    assert comparison.left_out >= 2
    # The same arithmetic: equal but for the yaw's round trip through a quaternion (ulps).
    assert comparison.worst["pose"] <= 1e-15 and comparison.worst["quality"] == 0


def test_a_taken_scan_missing_from_the_recording_stops_the_comparison_with_why():
    run, taken = a_run_that_leaves_scans_out()
    missing = taken[2]
    records = [r for r in run.records
               if not (r.topic == "/scan" and r.msg.header.stamp.sec * SECOND
                       + r.msg.header.stamp.nanosec == missing)]
    comparison = replay_records(records, run.values, 1e-9)
    assert not comparison.equal
    assert "not in the recording" in comparison.differences[-1]
    assert comparison.compared == 2


def test_a_lost_quality_is_a_difference_not_a_wrong_pairing():
    run, taken = a_run_that_leaves_scans_out()
    qualities = [i for i, r in enumerate(run.records) if r.topic == "/localization_quality"]
    del run.records[qualities[3]]
    comparison = replay_records(run.records, run.values, 1e-9)
    assert len(comparison.differences) == 1
    assert "localization_quality is not in the recording" in comparison.differences[0]


@pytest.mark.parametrize("left_out", [(), (1,), (2, 3, 4, 5)])
def test_any_choice_of_scans_replays_equal(left_out):
    run, taken = a_run_that_leaves_scans_out(left_out=left_out)
    comparison = replay_records(run.records, run.values, 1e-9)
    assert comparison.equal, comparison.differences
    assert comparison.compared == len(taken)


def without_outputs_before(records: list[Recorded], stamp_ns: int) -> list[Recorded]:
    """The recording of a recorder that heard the localizer when it published the update
    at ``stamp_ns``: no output before it (latched, depth 1: the latest only)."""
    first = next(i for i, r in enumerate(records)
                 if r.topic == "/pose" and r.msg.header.stamp.sec * SECOND
                 + r.msg.header.stamp.nanosec == stamp_ns)
    outputs = ("/pose", "/localization_quality")
    return [r for i, r in enumerate(records) if r.topic not in outputs or i >= first - 1]


def test_a_recorder_that_heard_the_localizer_late_replays_from_the_rule():
    run, taken = a_run_that_leaves_scans_out(left_out=(9,))
    assert taken[:3] == [stamp_of(0), stamp_of(2), stamp_of(4)]     # before the reset
    records = without_outputs_before(run.records, taken[2])
    comparison = replay_records(records, run.values, 1e-9)
    assert comparison.equal, comparison.differences
    assert comparison.assumed == 2 and comparison.compared == len(taken) - 2


def test_a_scan_left_out_before_the_recorder_heard_the_localizer_is_found_out():
    run, taken = a_run_that_leaves_scans_out(left_out=(2,))
    assert taken[:3] == [stamp_of(0), stamp_of(3), stamp_of(5)]     # before the reset
    records = without_outputs_before(run.records, taken[2])
    comparison = replay_records(records, run.values, 1e-9)
    assert len(comparison.differences) == 1
    assert "the first output recorded" in comparison.differences[0]
