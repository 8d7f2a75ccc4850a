"""grid_localizer: grid Markov localization on a map, with OccupancyGrid, LaserScan and odometry;
a drop-in for nav2_amcl (docs/nodes/grid_localizer.md compares the two).

A lifecycle node, as AMCL: Nav2's lifecycle manager configures and activates it (or
``autostart``); nothing is taken or published unless it is active. Odometry comes from
the tf tree as AMCL takes it (``odom_frame_id`` -> ``base_frame_id`` at each scan's time,
and the laser's mount from ``base_frame_id`` to the scan's frame), or from the ``odom``
topic (``odometry_source: topic``, the package's simulator). After each scan it publishes
``global_frame_id`` -> ``odom_frame_id`` on /tf, stamped with the scan's time plus
``transform_tolerance``, so that the tree's map -> base_link is the published pose.

The belief over (x, y, heading) starts uniform over the free cells: the
robot need not be told where it is. ``odom`` is followed continuously; a
``scan`` updates the belief once the robot moved ``update_min_d`` or turned
``update_min_a`` since the last update (core/grid/localization.py). After each
update: ``pose`` (the most likely state, with the belief's covariance around
it), ``belief_map`` (the belief's maximum over headings, 0..100, on the
state grid: RViz's Map display and Foxglove's 3D panel draw it) and
``localization_quality`` (the belief's probability near that pose), the
quality first. Bad messages are dropped and counted, never a NaN belief.

A scan waits up to ``odom_wait`` (``transform_tolerance`` with odometry from tf) for the
odometry of its time and is dropped if it does not come; scans that come while others
wait queue behind them (up to WAITING_SCANS, the oldest superseded beyond) and are taken
in order as their odometry comes.
Each published pose carries the stamp of what made it: its scan's time, the
initial pose's, or the time of a start or reset (uniform belief). So a
replay of a recorded run (tools/replay/grid_localizer.py) takes exactly the
scans this node took, whichever it left out.

Only the newest scan is kept while an update runs: an update that takes longer than the
laser's period answers the latest scan next, and ``/diagnostics`` says so (WARN, with
``scans_missed`` counted from the scans' stamps and scan_time, nodes/scan_gaps.py, and
``busy_percent``, the share of the time spent answering scans: update, estimate, publish).
"""

from __future__ import annotations

import math
import time
from collections import Counter, deque
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Pose, PoseArray, PoseWithCovarianceStamped
from nav_msgs.msg import OccupancyGrid, Odometry
from rclpy.lifecycle import LifecycleState, TransitionCallbackReturn
from rclpy.time import Time
from sensor_msgs.msg import LaserScan
from std_msgs.msg import Float64
from std_srvs.srv import Empty, Trigger

from estimation_nodes.core import errors
from estimation_nodes.core.grid import failure
from estimation_nodes.core.grid.model import GridModel
from estimation_nodes.core.grid.localization import (GridLocalization,
                                                     OdometryStep)
from estimation_nodes.core.transforms.buffer import (Extrapolation, LookupFailed,
                                                     TransformBuffer)
from estimation_nodes.core.transforms.rigid import Transform
from estimation_nodes.nodes.diagnostics import status_array
from estimation_nodes.nodes.lifecycle import ManagedNode
from estimation_nodes.nodes.grid_messages import (
    covariance_3x3,
    fill_pose,
    finite_pose,
    occupancy_grid,
    occupancy_of,
    planar_pose,
    pose_with_covariance,
    scan_beams,
)
from estimation_nodes.nodes.parameters import declare_and_build
from estimation_nodes.nodes.process import main_for
from estimation_nodes.nodes.qos import NEWEST_SCAN_QOS, latched_qos
from estimation_nodes.nodes.scan_gaps import ScanGaps
from estimation_nodes.nodes.stamps import stamp_or_none
from estimation_nodes.nodes.tf import TransformBroadcaster, TransformListener, to_message
from estimation_nodes.nodes.throttled import ThrottledWarnings
from estimation_nodes.params import topics
from estimation_nodes.params.grid import AMCL_INITIAL_COVARIANCE, build_grid_localizer_settings
from estimation_nodes.params.specs import GRID_LOCALIZER_SPECS

#: How often a waiting scan is checked against its ``odom_wait`` (s). A scan that waited
#: that long for the odometry of its time is dropped, as tf's message filter drops it:
#: used with an older odometry pose, its update would depend on when messages arrived,
#: and no replay of the recorded run could make it again.
SCAN_WAIT_CHECK_S = 0.05
#: Scans kept waiting for the odometry of their times, oldest first. A real log's
#: scans come in pairs 0.05 s apart where its odometry comes 0.9 s late: one slot lost
#: the first of each pair (4 of Intel's 889 updates at its own rate). Bounded, so late
#: odometry cannot queue more catching up than a second of a 10 Hz laser.
WAITING_SCANS = 10
#: Odometry messages queued while an update runs: 10 s at 200 Hz, so an update that keeps
#: the localizer busy loses none. A lost run of them makes the next one look like a jump
#: past max_odom_jump, dropped (a real log's odometry plays at 160 Hz beside a 10 Hz laser:
#: 200 messages were 1.25 s, which a loaded machine's update outlasted).
ODOM_DEPTH = 2000
#: Updates whose durations /diagnostics summarizes (the latest ones).
UPDATE_TIMES_KEPT = 1000
#: Updating this share of the time or more is falling behind the laser: a scan that comes
#: during an update waits, and one after it replaces it (WARN in /diagnostics). Counted
#: directly where the scans carry their period (scan_time): scans_missed.
BUSY_WARNING = 0.9
#: /tf messages queued while an update runs: every odom -> base_link sample is followed
#: (a lost one would move the next update's prediction and no replay could make it
#: again), as ODOM_DEPTH for the odom topic; a robot's /tf also carries its other frames.
TF_DEPTH = 5000
#: States shown in particle_cloud (RViz's PoseArray): the most probable ones.
PARTICLE_CLOUD_STATES = 500


class GridLocalizer(ManagedNode):
    """Where the robot is on the map, as an exact grid belief."""

    node_name = "grid_localizer"

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(self.node_name, **kwargs)
        _, self._settings = declare_and_build(
            self, GRID_LOCALIZER_SPECS, build_grid_localizer_settings)
        self._frames = self._settings.frames
        self.handled: Counter[str] = Counter()
        self.rejected: Counter[str] = Counter()
        self._warnings = ThrottledWarnings(self.get_logger())
        self.localization: GridLocalization | None = None
        self.last_update_s = float("nan")
        #: The durations (s) of the latest updates, for /diagnostics' median and maximum.
        self.update_times: deque[float] = deque(maxlen=UPDATE_TIMES_KEPT)
        self.tf_buffer = TransformBuffer()
        self._tf_listener: TransformListener | None = None
        #: map -> odom as of the last update (None before the first), sent again after each
        #: scan with its stamp, as AMCL does between updates.
        self._map_odom: Transform | None = None
        self._laser_mounts: dict[str, tuple[float, float, float]] = {}
        self._pending_initial_pose: PoseWithCovarianceStamped | None = None
        self._force_update = False
        #: Localized, uncertain or lost, and why (core/grid/failure.py), as of the last
        #: estimate published: /diagnostics goes out at once when it changes.
        self.standing: tuple[failure.Standing, str] | None = None
        self.start_if_asked()

    # --- lifecycle ---------------------------------------------------------------------------

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        latched = latched_qos(self._settings.history_depth)
        self._pose_pub = self.create_lifecycle_publisher(PoseWithCovarianceStamped,
                                                         topics.POSE, latched)
        self._belief_pub = self.create_lifecycle_publisher(OccupancyGrid, topics.BELIEF_MAP,
                                                           latched)
        self._quality_pub = self.create_lifecycle_publisher(Float64,
                                                            topics.LOCALIZATION_QUALITY, latched)
        self._cloud_pub = self.create_lifecycle_publisher(PoseArray, topics.PARTICLE_CLOUD,
                                                          latched_qos(1))
        self._diagnostics_pub = self.create_lifecycle_publisher(DiagnosticArray, "/diagnostics",
                                                                10)
        self._pose_msg = PoseWithCovarianceStamped()
        # A transform stamped further ahead of the node's clock than the tolerance (0.5 s at
        # least: clocks of two processes differ) is a clock or a driver gone wrong:
        # dropped and counted (tf_dropped.future).
        self._tf_listener = TransformListener(
            self, self.tf_buffer, round(max(self._frames.transform_tolerance, 0.5) * 1e9),
            on_jump_back=self._on_time_jump_back, on_transforms=self._on_transforms,
            depth=TF_DEPTH) \
            if self._frames.odometry_from_tf else None
        self._tf_broadcaster = TransformBroadcaster(self) if self._frames.tf_broadcast else None
        self.configured_publishers = [self._pose_pub, self._belief_pub, self._quality_pub,
                                      self._cloud_pub, self._diagnostics_pub]
        subscribe, made = self.create_subscription, self.configured_handles
        if self._settings.model is None:
            made.append(subscribe(OccupancyGrid, topics.MAP, self._on_map, latched_qos(1)))
        # A scan is only worth its latest, while odometry is followed in order.
        made.append(subscribe(LaserScan, topics.SCAN, self._on_scan, NEWEST_SCAN_QOS))
        self.scan_gaps = ScanGaps()
        self._missed_reported = 0
        #: Time spent updating since the last /diagnostics, and when that was (monotonic s).
        self._busy_s = 0.0
        self._reported_at = time.monotonic()
        if not self._frames.odometry_from_tf:
            made.append(subscribe(Odometry, topics.ODOM, self._on_odom, ODOM_DEPTH))
        made.append(subscribe(PoseWithCovarianceStamped, topics.INITIAL_POSE,
                              self._on_initial_pose, 10))
        made.append(self.create_service(Trigger, "~/global_localization",
                                        self._on_global_localization))
        made.append(self.create_service(Trigger, "~/reset", self._on_reset))
        # nav2_amcl's own services, by its names and types.
        made.append(self.create_service(Empty, "reinitialize_global_localization",
                                        self._on_reinitialize_global_localization))
        made.append(self.create_service(Empty, "request_nomotion_update",
                                        self._on_nomotion_update))
        made.append(self.create_timer(self._settings.diagnostics_period,
                                      self._publish_diagnostics))
        #: Scans waiting for the odometry of their times: (message, stamp ns, deadline).
        self._waiting_scans: deque[tuple[LaserScan, int, float]] = deque()
        made.append(self.create_timer(min(SCAN_WAIT_CHECK_S, self._scan_wait_s() / 4),
                                      self._scan_waited_out))
        if self._settings.model is not None:
            self._start(self._settings.model)
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        result = super().on_activate(state)
        initial = self._frames.initial_pose
        if initial is not None and self.localization is not None:
            self._set_prior(initial, np.diag(AMCL_INITIAL_COVARIANCE), None)
        elif self._pending_initial_pose is not None:
            self._on_initial_pose(self._pending_initial_pose)
        elif self.localization is not None:
            self._publish()
        self._pending_initial_pose = None
        return result

    def forget(self) -> None:
        """At cleanup: the belief, the tf buffer and what was learnt of the mount."""
        if self._tf_listener is not None:
            self._tf_listener.destroy()
        self.tf_buffer = TransformBuffer()
        self.localization = None
        self._map_odom = None
        self._laser_mounts = {}

    def _scan_wait_s(self) -> float:
        return self._frames.transform_tolerance if self._frames.odometry_from_tf \
            else self._settings.odom_wait

    def _start(self, model: GridModel) -> None:
        self.localization = self._settings.localization(model)
        rows, cols = model.free.shape
        self.get_logger().info(
            f"ready: {cols} x {rows} cells of {model.resolution} m, {model.heading_bins} "
            f"headings ({model.free.sum() * model.heading_bins} free states); belief uniform "
            f"over the free cells")
        if self._frames.laser_pose is not None or not self._frames.odometry_from_tf:
            self.localization.set_laser_pose(self._frames.laser_pose or (0.0, 0.0, 0.0))
        if self.active:
            self._publish()

    def _on_time_jump_back(self) -> None:
        """Time went back (a bag played again): start over, as AMCL does."""
        if self.localization is not None:
            self.localization = self._settings.localization(self.localization.model)
        self._waiting_scans.clear()
        self._map_odom = None
        self.handled["time_jumped_back"] += 1
        self.get_logger().warning("time jumped back: the belief is uniform again")

    # --- inputs -----------------------------------------------------------------------------

    def _on_map(self, msg: OccupancyGrid) -> None:
        try:
            model = self._settings.model_for(occupancy_of(msg))
        except errors.MapError as error:
            self._reject("bad_map", f"map dropped: {error}")
            return
        self.handled["map"] += 1
        self._start(model)

    def _on_odom(self, msg: Odometry) -> None:
        pose = planar_pose(msg.pose.pose)
        if not finite_pose(pose):
            self._reject("non_finite_odom", "odom dropped: its pose is not finite")
            return
        if self.localization is None or not self.active:
            return
        if self._take_odometry(pose, stamp_or_none(msg.header.stamp)):
            self._use_waiting_scans()

    def _take_odometry(self, pose: tuple[float, float, float], stamp: int | None) -> bool:
        """Follow one odometry pose (a message's, or the tree's at a scan's time)."""
        assert self.localization is not None
        step = self.localization.on_odometry(pose, stamp)
        if step is OdometryStep.JUMP:
            self._reject("odom_jump", f"odom jumped more than {self._settings.max_odom_jump} m:"
                         " not taken as motion; followed from the new pose")
            return False
        if step is OdometryStep.REPEATED_STAMP:
            # Not a fault of the message: real logs repeat stamps (a driver polling faster
            # than its clock ticks). Counted, and said once.
            if not self.handled["odom_repeated_stamp"]:
                self.get_logger().info("odom repeats a stamp: the first pose at a time is "
                                       "kept, later ones ignored (handled.odom_repeated_stamp)")
            self.handled["odom_repeated_stamp"] += 1
            return False
        self.handled["odom"] += 1
        return True

    def _use_waiting_scans(self) -> None:
        """The waiting scans whose odometry came, in order."""
        waiting = self._waiting_scans
        while waiting and self.localization is not None:
            ready, odometry = self._scan_odometry(*waiting[0][:2])
            if not ready:
                return
            msg, stamp, _ = waiting.popleft()
            self._use_scan(msg, stamp, odometry)

    def _on_transforms(self, taken: list) -> None:
        """From tf: each odom -> base_link sample followed as odometry (as the odom topic's
        messages are), then the waiting scans looked at again."""
        if self.localization is None or not self.active:
            return
        for parent, child, stamp, transform in taken:
            if (parent, child) == (self._frames.odom_frame_id, self._frames.base_frame_id):
                self._take_odometry(transform.as_planar(), stamp)
        self._use_waiting_scans()

    def _scan_odometry(self, msg: LaserScan, stamp: int
                       ) -> tuple[bool, tuple[float, float, float] | None]:
        """Whether the odometry of a scan's time is known, and from tf that odometry (the
        tree's, interpolated at the scan's time) with the laser's mount taken."""
        assert self.localization is not None
        if not self._frames.odometry_from_tf:
            return self.localization.odometry_covers(stamp), None
        frames = self._frames
        try:
            odom_base = self.tf_buffer.lookup(frames.odom_frame_id, frames.base_frame_id, stamp)
            mount = self._laser_mount(msg.header.frame_id, stamp)
        except Extrapolation:
            return False, None      # the transforms of its time are still on their way
        except LookupFailed as error:
            self._warnings.warn("tf_lookup", f"scan waits: {error}")
            return False, None
        self.localization.set_laser_pose(mount)
        return True, odom_base.as_planar()

    def _laser_mount(self, frame: str, stamp: int) -> tuple[float, float, float]:
        """The laser's (x, y, yaw) on the robot: the parameter, or the tree's (kept once
        found: a mount is static)."""
        if self._frames.laser_pose is not None:
            return self._frames.laser_pose
        if frame in ("", self._frames.base_frame_id):
            return (0.0, 0.0, 0.0)
        if frame not in self._laser_mounts:
            mount = self.tf_buffer.lookup(self._frames.base_frame_id, frame, stamp).as_planar()
            self._laser_mounts[frame] = mount
            self.get_logger().info(
                f"laser mount from tf: {frame} at ({mount[0]:.3f}, {mount[1]:.3f}) m, "
                f"{math.degrees(mount[2]):.1f} deg in {self._frames.base_frame_id}")
        return self._laser_mounts[frame]

    def _scan_waited_out(self) -> None:
        waiting = self._waiting_scans
        while waiting and time.monotonic() > waiting[0][2]:
            waiting.popleft()
            if self._frames.odometry_from_tf:
                self._reject("scan_without_transform", "scan dropped: the transforms of its "
                             f"time did not come within transform_tolerance "
                             f"({self._frames.transform_tolerance:g} s)")
            else:
                self._reject("scan_without_odometry", f"scan dropped: no odometry of its time "
                             f"came within odom_wait ({self._settings.odom_wait:g} s)")
        self._use_waiting_scans()

    def _on_scan(self, msg: LaserScan) -> None:
        if self.localization is None or not self.active:
            return
        if not (math.isfinite(msg.angle_increment) and msg.angle_increment != 0
                and math.isfinite(msg.angle_min)):
            self._reject("bad_scan", f"scan dropped: angle_increment {msg.angle_increment}, "
                         f"angle_min {msg.angle_min}")
            return
        stamp = stamp_or_none(msg.header.stamp)
        self.scan_gaps.note(stamp, msg.scan_time)
        if stamp is None and self._frames.odometry_from_tf:
            self._reject("unstamped_scan", "scan dropped: no stamp to look its transforms up at")
            return
        ready, odometry = (False, None) if stamp is None or self._waiting_scans \
            else self._scan_odometry(msg, stamp)
        if stamp is not None and not ready:
            # The odometry of the scan's time is still on its way (another topic): wait for
            # it, so the update does not depend on which came first; behind older scans
            # that wait, to keep their order.
            if len(self._waiting_scans) == WAITING_SCANS:
                self._waiting_scans.popleft()
                self.handled["scan_superseded"] += 1
            self._waiting_scans.append((msg, stamp, time.monotonic() + self._scan_wait_s()))
            self._use_waiting_scans()
            return
        self._use_scan(msg, stamp, odometry)

    def _use_scan(self, msg: LaserScan, stamp: int | None,
                  odometry: tuple[float, float, float] | None = None) -> None:
        """Update with a scan whose odometry is known (``odometry``: tf's at its time)."""
        assert self.localization is not None
        if not (self.localization.due(stamp, odometry) or self._force_update):
            self.handled["scan_without_motion"] += 1
            self._broadcast(stamp)
            return
        ranges, angles, nan = scan_beams(msg, self._settings.sensor.max_range,
                                         self._settings.max_beams)
        if nan:
            self.rejected["nan_ranges"] += nan
        started = time.perf_counter()
        try:
            self.localization.update(ranges, angles, stamp, odometry)
        except errors.ZeroEvidenceError as error:
            self._reject("zero_evidence", f"scan dropped: {error}")
            return
        except errors.EstimationError as error:   # what scan_beams let through, or the motion
            self._reject("bad_scan", f"scan dropped: {error}")
            return
        self._force_update = False
        self.last_update_s = time.perf_counter() - started
        self.update_times.append(self.last_update_s)
        self.handled["scan"] += 1
        estimate = self._publish(Time.from_msg(msg.header.stamp))
        self._map_odom = self._map_to_odom(estimate.pose, stamp, odometry)
        self._broadcast(stamp)
        # Busy: the whole answer to the scan, the estimate (its scan fit) and the publishing
        # included.
        self._busy_s += time.perf_counter() - started

    def _map_to_odom(self, pose: tuple[float, float, float], stamp: int | None,
                     odometry: tuple[float, float, float] | None) -> Transform | None:
        """map -> odom such that map -> odom -> base_link at the scan's time is ``pose``."""
        assert self.localization is not None
        odometry = odometry or self.localization.odometry_at(stamp)
        if odometry is None:
            return None
        return Transform.planar(*pose) * Transform.planar(*odometry).inverse()

    def _broadcast(self, stamp: int | None) -> None:
        """map -> odom on /tf, future-dated by transform_tolerance (AMCL's meaning)."""
        if self._tf_broadcaster is None or self._map_odom is None:
            return
        now = stamp if stamp is not None else self.get_clock().now().nanoseconds
        stamp_ns = now + round(self._frames.transform_tolerance * 1e9)
        self._tf_broadcaster.send([to_message(self._frames.global_frame_id,
                                              self._frames.odom_frame_id, stamp_ns,
                                              self._map_odom)])

    def _on_initial_pose(self, msg: PoseWithCovarianceStamped) -> None:
        pose = planar_pose(msg.pose.pose)
        covariance = covariance_3x3(msg.pose.covariance)
        if not (finite_pose(pose) and np.isfinite(covariance).all()):
            self._reject("bad_initialpose", "initialpose dropped: not finite")
            return
        if not self.active:
            self._pending_initial_pose = msg     # taken at activation, as AMCL does
            return
        if self.localization is None:
            return
        stamp = Time.from_msg(msg.header.stamp) if stamp_or_none(msg.header.stamp) is not None \
            else None
        self._set_prior(pose, covariance, stamp)

    def _set_prior(self, pose: tuple[float, float, float], covariance: np.ndarray,
                   stamp: Time | None) -> None:
        assert self.localization is not None
        try:
            self.localization.set_prior(pose, covariance)
        except errors.EstimationError as error:   # not a covariance, or singular
            self._reject("bad_initialpose", f"initialpose dropped: {error}")
            return
        self.handled["initialpose"] += 1
        self.get_logger().info(f"initial pose ({pose[0]:.2f}, {pose[1]:.2f}, "
                               f"{math.degrees(pose[2]):.0f} deg) taken as the prior")
        # Stamped with the initial pose's time: the belief as of that prior (and a replay
        # of the run tells it from an update by that stamp).
        self._publish(stamp)

    def _on_global_localization(self, _request, response: Trigger.Response):
        if self.localization is None or not self.active:
            response.success = False
            response.message = "no map yet" if self.active else "not active"
            return response
        self.localization.global_localization()
        self._publish()
        response.success = True
        response.message = "belief uniform over the free cells"
        return response

    def _on_reset(self, request, response: Trigger.Response):
        return self._on_global_localization(request, response)

    def _on_reinitialize_global_localization(self, _request, response: Empty.Response):
        """nav2_amcl's service: the belief uniform over the free cells."""
        self._on_global_localization(None, Trigger.Response())
        return response

    def _on_nomotion_update(self, _request, response: Empty.Response):
        """nav2_amcl's service: the next scan updates the belief without motion."""
        self._force_update = True
        return response

    # --- outputs ----------------------------------------------------------------------------

    def _publish(self, stamp: Time | None = None):
        assert self.localization is not None
        model = self.localization.model
        estimate = self.localization.estimate(self._settings.quality_radius,
                                              self._settings.quality_angle)
        if not self.active:
            return estimate
        stamp_msg = (stamp or self.get_clock().now()).to_msg()
        frame = self._frames.global_frame_id
        # The quality first, then its pose. A subscriber pairs them by this order of
        # publication (the source timestamps), not by the order its callbacks run, which
        # may take a ready pose before the quality that came with it (tools/demo/grid_run.py).
        self._quality_pub.publish(Float64(data=estimate.quality))
        msg = pose_with_covariance(self._pose_msg, estimate.pose, estimate.covariance)
        msg.header.stamp = stamp_msg
        msg.header.frame_id = frame
        self._pose_pub.publish(msg)
        self._belief_pub.publish(occupancy_grid(self.localization.belief_map(),
                                                model.resolution, model.origin, frame,
                                                stamp_msg))
        if self._cloud_pub.get_subscription_count():
            self._cloud_pub.publish(self._particle_cloud(stamp_msg))
        was = self.standing
        self.standing = self.localization.standing(estimate, self._settings.quality_radius,
                                                   self._settings.quality_angle)
        if was is None or was[0] is not self.standing[0]:
            # A behaviour tree acts on it: said with this update, not at the next period.
            self._publish_diagnostics()
        return estimate

    def _particle_cloud(self, stamp_msg) -> PoseArray:
        assert self.localization is not None
        cloud = PoseArray()
        cloud.header.stamp, cloud.header.frame_id = stamp_msg, self._frames.global_frame_id
        for (x, y, yaw), _ in self.localization.most_likely_states(PARTICLE_CLOUD_STATES):
            pose = Pose()
            fill_pose(pose, x, y, yaw)
            cloud.poses.append(pose)
        return cloud

    def update_time_figures(self) -> dict[str, float]:
        """The latest updates' times (ms): median, 99th percentile, maximum."""
        times = np.asarray(self.update_times) * 1e3
        return {"median": float(np.median(times)), "p99": float(np.percentile(times, 99)),
                "max": float(times.max())}

    def _busy_since_last_report(self) -> float:
        """The share of the time since the last report spent in updates (0..1)."""
        now = time.monotonic()
        busy = min(1.0, self._busy_s / max(now - self._reported_at, 1e-9))
        self._busy_s, self._reported_at = 0.0, now
        return busy

    def _reject(self, reason: str, message: str) -> None:
        self.rejected[reason] += 1
        self._warnings.warn(reason, f"{message} (rejected so far: {self.rejected[reason]})")

    def _publish_diagnostics(self) -> None:
        if not self.active:
            return
        values: dict[str, Any] = {"map": "waiting for map" if self.localization is None
                                  else "loaded"}
        if self.localization is not None:
            estimate = self.localization.estimate(self._settings.quality_radius,
                                                  self._settings.quality_angle)
            values.update({
                "pose_x": f"{estimate.pose[0]:.3f}", "pose_y": f"{estimate.pose[1]:.3f}",
                "pose_yaw_deg": f"{math.degrees(estimate.pose[2]):.1f}",
                "quality": f"{estimate.quality:.4f}",
                "belief_entropy_bits": f"{self.localization.entropy_bits():.4f}",
                "updates": self.localization.updates,
                "window_states": self.localization.window_states,
                "last_dropped_probability": f"{self.localization.last_dropped:.3g}",
                "lost_probability": f"{self.localization.lost_probability:.3g}",
            })
            if self.standing is not None:
                values.update({"localization_state": self.standing[0].value,
                               "localization_reason": self.standing[1]})
            if math.isfinite(self.localization.log_evidence):
                values["last_log_evidence"] = f"{self.localization.log_evidence:.4f}"
            if math.isfinite(self.last_update_s):
                values["last_update_ms"] = f"{self.last_update_s * 1e3:.1f}"
                values.update({f"update_ms_{name}": f"{ms:.1f}"
                               for name, ms in self.update_time_figures().items()})
        busy = self._busy_since_last_report()
        values.update({"scans_received": self.scan_gaps.received,
                       "scans_missed": self.scan_gaps.missed,
                       "busy_percent": f"{100 * busy:.0f}"})
        values.update({f"handled.{k}": v for k, v in sorted(self.handled.items())})
        values.update({f"rejected.{k}": v for k, v in sorted(self.rejected.items())})
        if self._tf_listener is not None:
            values.update({f"tf_dropped.{k}": v
                           for k, v in sorted(self._tf_listener.dropped.items())})
        problems = ["messages rejected"] if self.rejected else []
        lost = self.standing is not None and self.standing[0] is failure.Standing.LOST
        if self.standing is not None and self.standing[0] is not failure.Standing.LOCALIZED:
            problems.insert(0, f"{self.standing[0].value}: {self.standing[1]}")
        missed_now = self.scan_gaps.missed - self._missed_reported
        self._missed_reported = self.scan_gaps.missed
        if missed_now:
            problems.append(f"falling behind the laser: {missed_now} scans missed since the "
                            f"last report")
        elif busy >= BUSY_WARNING:
            problems.append(f"falling behind the laser: updating {100 * busy:.0f}% of the "
                            f"time, newer scans replace those waiting")
        self._diagnostics_pub.publish(status_array(self, "grid localization", values,
                                                   problems, error=lost))


main = main_for(GridLocalizer)

if __name__ == "__main__":
    main()

