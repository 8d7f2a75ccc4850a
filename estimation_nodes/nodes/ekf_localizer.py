"""ekf_localizer: where the robot is among known landmarks, by an EKF or a UKF.

``odom`` (nav_msgs/Odometry) drives the unicycle with its twist (linear.x,
angular.z) until the next event; ``landmark_observations``
(sensor_msgs/PointCloud2, one message per camera frame, fields x, y, z float32
and id uint32: the landmark in the sensor frame) corrects it by range and
bearing. Events are applied in the order of their stamps, whatever order they
arrive in (core/causal_order.py). After every event that changes the estimate,
``pose`` (PoseWithCovarianceStamped in ``frame_id``, stamped with the event's
time). The filter, its gate and its recovery are core/kalman/landmarks.py.

As grid_localizer, a lifecycle node (``autostart`` to run alone: nothing is taken or
published unless it is active), and after each odometry message that is the newest
event, ``frame_id -> odom_frame_id`` on /tf: the estimate composed with the inverse of
that message's own pose, stamped with its time plus ``transform_tolerance``, so that the
tree's map -> base_link is the estimate.
"""

from __future__ import annotations

import math
from collections import Counter
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseWithCovarianceStamped
from nav_msgs.msg import Odometry
from rcl_interfaces.msg import SetParametersResult
from rclpy.lifecycle import LifecycleState, TransitionCallbackReturn
from rclpy.parameter import Parameter
from sensor_msgs.msg import PointCloud2
from std_srvs.srv import Trigger

from estimation_nodes.core.causal_order import CausalOrder
from estimation_nodes.core.kalman import ukf
from estimation_nodes.core.kalman.landmarks import LandmarkLocalization
from estimation_nodes.core.transforms.rigid import Transform
from estimation_nodes.nodes.diagnostics import status_array
from estimation_nodes.nodes.grid_messages import planar_pose, pose_with_covariance
from estimation_nodes.nodes.lifecycle import ManagedNode
from estimation_nodes.nodes.landmark_messages import (
    MalformedCloudError,
    initial_pose_of,
    landmark_points,
)
from estimation_nodes.nodes.parameters import declare_and_build, overlay, rejection
from estimation_nodes.nodes.process import main_for
from estimation_nodes.nodes.qos import INPUT_QOS, latched_qos
from estimation_nodes.nodes.stamps import stamp_or_none
from estimation_nodes.nodes.tf import TransformBroadcaster, to_message
from estimation_nodes.nodes.throttled import ThrottledWarnings
from estimation_nodes.params import topics
from estimation_nodes.params.landmarks import build_ekf_localizer_settings
from estimation_nodes.params.specs import EKF_LOCALIZER_SPECS

#: An odometry message sorts before a camera frame of the same stamp: the motion up to
#: the frame is applied before what the frame saw.
ODOM_RANK, FRAME_RANK = 0, 1
#: The most events the reorder history keeps, whatever reorder_horizon allows.
MAX_REORDER_EVENTS = 10_000
class _Events:
    """The filter as core/causal_order.py replays it: an event is ('odom', t, v, w) or
    ('frame', t, observations)."""

    def __init__(self, localization: LandmarkLocalization) -> None:
        self.localization = localization
        self.last_outcomes: list = []

    def snapshot(self) -> tuple:
        return self.localization.snapshot()

    def restore(self, state: tuple) -> None:
        self.localization.restore(state)

    def apply(self, event: tuple, first_time: bool) -> bool:
        kind, t = event[0], event[1]
        if kind == "odom":
            self.localization.on_odometry(t, event[2], event[3])
        else:
            outcomes = self.localization.on_frame(t, event[2])
            if first_time:
                self.last_outcomes = outcomes
        return True


class EkfLocalizer(ManagedNode):
    """The robot's pose among landmarks, as an EKF or a UKF estimate."""

    node_name = "ekf_localizer"

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(self.node_name, **kwargs)
        self._values, self._settings = declare_and_build(
            self, EKF_LOCALIZER_SPECS, build_ekf_localizer_settings)
        self._landmarks = dict(self._settings.model.landmarks)
        if self._settings.model.kind == "ukf":
            ukf.prepare_compiled()
        self.handled: Counter[str] = Counter()
        self.rejected: Counter[str] = Counter()
        self._warnings = ThrottledWarnings(self.get_logger())
        self._events: _Events | None = None
        self._order: CausalOrder | None = None
        self._nis: list[float] = []
        #: The stamp of the newest event applied: what the estimate is as of.
        self._newest_ns = 0
        self._pose_msg = PoseWithCovarianceStamped()
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self._initial = (self._settings.initial_pose, self._settings.initial_covariance)
        self._tf_broadcaster: TransformBroadcaster | None = None
        self.start_if_asked()

    # --- lifecycle ---------------------------------------------------------------------------

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._pose_pub = self.create_lifecycle_publisher(
            PoseWithCovarianceStamped, topics.POSE, latched_qos(self._values["history_depth"]))
        self._diagnostics_pub = self.create_lifecycle_publisher(DiagnosticArray,
                                                                topics.DIAGNOSTICS, 10)
        self.configured_publishers = [self._pose_pub, self._diagnostics_pub]
        if self.get_parameter("tf_broadcast").value:
            self._tf_broadcaster = TransformBroadcaster(self)
        self.configured_handles = [
            self.create_subscription(Odometry, topics.ODOM, self._on_odom, INPUT_QOS),
            self.create_subscription(PointCloud2, topics.LANDMARK_OBSERVATIONS,
                                     self._on_landmarks, INPUT_QOS),
            self.create_subscription(PoseWithCovarianceStamped, topics.INITIAL_POSE,
                                     self._on_initial_pose, 10),
            self.create_service(Trigger, "~/reset", self._on_reset),
            self.create_timer(self._settings.diagnostics_period, self._publish_diagnostics)]
        self.get_logger().info(
            f"ready: {self._settings.model.kind.upper()} among {len(self._landmarks)} "
            f"landmarks, from ({self._initial[0][0]:.2f}, {self._initial[0][1]:.2f}, "
            f"{math.degrees(self._initial[0][2]):.0f} deg)")
        return TransitionCallbackReturn.SUCCESS

    def forget(self) -> None:
        """At cleanup: the filter starts again from the initial pose."""
        self._tf_broadcaster = None
        self._restart()

    @property
    def localization(self) -> LandmarkLocalization | None:
        return self._events.localization if self._events is not None else None

    # --- inputs -----------------------------------------------------------------------------

    def _on_odom(self, msg: Odometry) -> None:
        if not self.active:
            return
        v, w = msg.twist.twist.linear.x, msg.twist.twist.angular.z
        stamp = stamp_or_none(msg.header.stamp)
        if not (math.isfinite(v) and math.isfinite(w)) or stamp is None:
            self._reject("bad_odom", f"odom dropped: twist ({v}, {w}) or stamp {stamp} unusable")
            return
        if self._submit(stamp, ODOM_RANK, ("odom", stamp / 1e9, v, w), "odom") \
                and stamp == self._newest_ns:
            self._broadcast(stamp, planar_pose(msg.pose.pose))

    def _on_landmarks(self, msg: PointCloud2) -> None:
        if not self.active:
            return
        stamp = stamp_or_none(msg.header.stamp)
        try:
            observations = landmark_points(msg)
        except MalformedCloudError as error:
            self._reject("malformed_landmarks", f"landmark_observations dropped: {error}")
            return
        if stamp is None:
            self._reject("unstamped_landmarks", "landmark_observations dropped: no stamp")
            return
        self._submit(stamp, FRAME_RANK, ("frame", stamp / 1e9, observations), "frame")

    def _submit(self, stamp: int, rank: int, event: tuple, kind: str) -> bool:
        """Apply an event in its place and publish; False when it was dropped."""
        if self._order is None:
            self._start()
        assert self._order is not None and self._events is not None
        self._events.last_outcomes = []
        try:
            submission = self._order.submit(stamp, rank, event)
        except ValueError as error:
            self._reject(f"bad_{kind}", f"{kind} dropped: {error}")
            return False
        self.handled[kind] += 1
        self._newest_ns = max(self._newest_ns, stamp)
        if submission.reordered:
            self.handled["events_reordered"] += 1
        if submission.too_late:
            self.handled["events_too_late"] += 1
        self._nis.extend(o.nis for o in self._events.last_outcomes if math.isfinite(o.nis))
        self._publish()
        return True

    def _start(self) -> None:
        """The filter from the initial pose, at the time of the earliest event it takes."""
        localization = LandmarkLocalization(self._settings.model, *self._initial)
        self._events = _Events(localization)
        self._order = CausalOrder(self._events, int(self._settings.reorder_horizon * 1e9),
                                  MAX_REORDER_EVENTS)

    def _on_initial_pose(self, msg: PoseWithCovarianceStamped) -> None:
        if not self.active:
            return
        try:
            pose, covariance = initial_pose_of(msg)
        except ValueError as error:
            self._reject("bad_initialpose", f"initialpose dropped: {error}")
            return
        self._initial = (pose, covariance)
        self._restart()
        self.handled["initialpose"] += 1
        self.get_logger().info(f"initial pose ({pose[0]:.2f}, {pose[1]:.2f}, "
                               f"{math.degrees(pose[2]):.0f} deg) taken")

    def _on_reset(self, _request, response: Trigger.Response) -> Trigger.Response:
        self._initial = (self._settings.initial_pose, self._settings.initial_covariance)
        self._restart()
        response.success, response.message = True, "estimate back to initial_pose"
        return response

    def _restart(self) -> None:
        """The filter starts again from ``_initial`` at the next event."""
        self._events, self._order, self._newest_ns = None, None, 0

    def _on_set_parameters(self, changes: list[Parameter]) -> SetParametersResult:
        """A change that builds valid settings is taken at once (for the events to come);
        any other is refused, and nothing changes."""
        proposed = overlay(self._values, changes)
        try:
            settings = build_ekf_localizer_settings(proposed, self._landmarks)
        except ValueError as error:
            return rejection(str(error))
        self._values, self._settings = proposed, settings
        if self._events is not None:
            self._events.localization.model = settings.model
        return SetParametersResult(successful=True)

    # --- outputs ----------------------------------------------------------------------------

    def _publish(self) -> None:
        localization = self.localization
        assert localization is not None
        msg = pose_with_covariance(self._pose_msg, tuple(localization.pose.tolist()),
                                   localization.pose_covariance)
        seconds, nanoseconds = divmod(self._newest_ns, 1_000_000_000)
        msg.header.stamp.sec, msg.header.stamp.nanosec = seconds, nanoseconds
        msg.header.frame_id = self._settings.frame_id
        self._pose_pub.publish(msg)

    def _broadcast(self, stamp: int, odometry: tuple[float, float, float]) -> None:
        """map -> odom: the estimate at ``stamp`` with the odometry's own pose then taken
        out, stamped ``transform_tolerance`` later."""
        localization = self.localization
        if self._tf_broadcaster is None or localization is None:
            return
        map_odom = Transform.planar(*localization.pose.tolist()) * \
            Transform.planar(*odometry).inverse()
        later = round(self.get_parameter("transform_tolerance").value * 1e9)
        self._tf_broadcaster.send([to_message(
            self._settings.frame_id, self.get_parameter("odom_frame_id").value,
            stamp + later, map_odom)])

    def _reject(self, reason: str, message: str) -> None:
        self.rejected[reason] += 1
        self._warnings.warn(reason, f"{message} (rejected so far: {self.rejected[reason]})")

    def _publish_diagnostics(self) -> None:
        if not self.active:
            return
        values: dict[str, Any] = {"filter": self._settings.model.kind}
        localization = self.localization
        if localization is not None:
            x, P = localization.pose, localization.pose_covariance
            values.update({"pose_x": f"{x[0]:.3f}", "pose_y": f"{x[1]:.3f}",
                           "pose_yaw_deg": f"{math.degrees(x[2]):.1f}",
                           "std_xy": f"{math.sqrt(max(P[0, 0], P[1, 1])):.3f}",
                           "lost": str(localization.lost).lower()})
            scale, scale_std = localization.range_scale
            if scale_std > 0:
                values.update({"range_scale": f"{scale:.4f}",
                               "range_scale_std": f"{scale_std:.4f}"})
            values.update({f"observations.{k}": v
                           for k, v in sorted(localization.counts.items())})
        if self._nis:
            values["nis_mean"] = f"{float(np.mean(self._nis)):.3f}"
            values["nis_last"] = f"{self._nis[-1]:.3f}"
            self._nis = self._nis[-1:]
        values.update({f"handled.{k}": v for k, v in sorted(self.handled.items())})
        values.update({f"rejected.{k}": v for k, v in sorted(self.rejected.items())})
        lost = localization is not None and localization.lost
        problems = ["lost: every observation gated"] if lost \
            else ["messages rejected"] if self.rejected else []
        self._diagnostics_pub.publish(status_array(self, "landmark localization", values,
                                                   problems))


main = main_for(EkfLocalizer)

if __name__ == "__main__":
    main()

