"""estimation_replay's landmark rules: which of ekf_localizer's poses can be held against the
offline filter (tools/replay/landmarks.py)."""

from __future__ import annotations

from geometry_msgs.msg import PoseWithCovarianceStamped

from estimation_nodes.tools.replay.grid_localizer import Recorded
from estimation_nodes.tools.replay.landmarks import POSE, Event, LandmarkComparison, _final_poses


def pose(stamp_ns: int, publish_ns: int) -> Recorded:
    msg = PoseWithCovarianceStamped()
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 10**9)
    return Recorded(POSE, publish_ns, msg)


def test_a_stamp_s_last_pose_is_compared_and_a_pose_before_a_late_event_is_not():
    second = 10**9
    events = [Event(1 * second, 0, 100, ("odom", 0.1, 0.0)),
              Event(1 * second, 1, 110, ("frame", [])),
              Event(2 * second, 0, 200, ("odom", 0.1, 0.0)),
              Event(3 * second, 0, 300, ("odom", 0.1, 0.0)),
              Event(second + second // 2, 1, 350, ("frame", []))]  # 1.5 s, late: after 3 s
    poses = [pose(1 * second, 105), pose(1 * second, 115),       # odometry, then the frame
             pose(2 * second, 205), pose(3 * second, 305),
             pose(3 * second, 355)]                              # the late frame answered
    comparison = LandmarkComparison()
    final = _final_poses(events, poses, comparison)
    # 1 s: its last pose; 2 s: published before the late frame of 1.5 s, not held;
    # 3 s: the pose after the late frame.
    assert {stamp: p.publish_ns for stamp, p in final.items()} == {1 * second: 115,
                                                                   3 * second: 355}
    assert comparison.provisional == 3
