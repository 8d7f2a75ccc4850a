"""estimation_replay's landmark rules: which of ekf_localizer's poses can be held against the
offline filter (tools/replay/landmarks.py)."""

from __future__ import annotations

import pytest
from geometry_msgs.msg import PoseWithCovarianceStamped

from estimation_nodes.nodes.landmark_messages import initial_pose_of
from estimation_nodes.tools.replay.grid_localizer import Recorded
from estimation_nodes.tools.replay.landmarks import (
    INITIAL_POSE,
    POSE,
    Event,
    LandmarkComparison,
    _before_too_late,
    _final_poses,
    runs_of,
)

SECOND = 10**9


def pose(stamp_ns: int, publish_ns: int) -> Recorded:
    msg = PoseWithCovarianceStamped()
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, SECOND)
    return Recorded(POSE, publish_ns, msg)


def odom(stamp_ns: int, publish_ns: int) -> Event:
    return Event(stamp_ns, 0, publish_ns, ("odom", 0.1, 0.0))


def frame(stamp_ns: int, publish_ns: int) -> Event:
    return Event(stamp_ns, 1, publish_ns, ("frame", []))


#: Odometry at 1 s, a frame of 1 s, odometry at 2 s, published in that order.
EVENTS = [odom(SECOND, 100), frame(SECOND, 110), odom(2 * SECOND, 200)]


def compared(poses) -> tuple[dict[int, int], int]:
    comparison = LandmarkComparison()
    final = _final_poses(EVENTS, poses, comparison)
    return {stamp // SECOND: p.publish_ns for stamp, p in final.items()}, comparison.provisional


def test_each_pose_is_compared_when_the_node_took_the_events_in_their_order():
    # one pose per event: after the odometry of 1 s, its frame, the odometry of 2 s
    assert compared([pose(SECOND, 105), pose(SECOND, 115), pose(2 * SECOND, 205)]) == (
        {1: 115, 2: 205}, 1)          # the first pose of 1 s came before the frame of 1 s


def test_a_pose_the_other_topic_s_queued_event_was_not_in_is_not_held_against_it():
    # The node took the odometry of 2 s before the frame of 1 s, still queued on its own
    # topic (published at 110, before the pose of 2 s): that pose lacks the frame, and the
    # last one (the frame answered as of 2 s) has everything.
    assert compared([pose(SECOND, 105), pose(2 * SECOND, 205), pose(2 * SECOND, 210)]) == (
        {2: 210}, 2)


def test_the_poses_after_an_event_later_than_the_horizon_are_not_compared():
    events = [odom(5 * SECOND, 100), odom(6 * SECOND, 200), frame(3 * SECOND, 300)]
    poses = [pose(5 * SECOND, 105), pose(6 * SECOND, 205), pose(6 * SECOND, 305)]
    comparison = LandmarkComparison()
    kept = _before_too_late(events, poses, 2.0, comparison)
    assert [p.publish_ns for p in kept] == [105, 205] and comparison.after_too_late == 1
    assert _before_too_late(events, poses, 5.0, LandmarkComparison()) == poses


def test_only_an_initialpose_the_node_takes_begins_a_run():
    def initialpose(x: float, variance: float) -> Recorded:
        msg = PoseWithCovarianceStamped()
        msg.pose.pose.position.x, msg.pose.pose.orientation.w = x, 1.0
        msg.pose.covariance[0] = msg.pose.covariance[7] = msg.pose.covariance[35] = variance
        return Recorded(INITIAL_POSE, 0, msg)

    runs = runs_of([initialpose(1.0, 0.1),                  # taken
                    initialpose(float("nan"), 0.1),         # not finite: refused
                    initialpose(2.0, 0.0)])                 # no positive definite covariance
    assert len(runs) == 2 and runs[0][0] is None
    pose, covariance = runs[1][0]
    assert pose.tolist() == [1.0, 0.0, 0.0] and covariance[0, 0] == 0.1
    with pytest.raises(ValueError, match="not finite"):
        initial_pose_of(initialpose(float("nan"), 0.1).msg)
