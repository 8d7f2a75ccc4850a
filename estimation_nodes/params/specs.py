"""Every node's parameters in one table: name, default, description, bounds.

No rclpy here: the nodes declare these specs (nodes/parameters.py), the
settings modules turn their values into core models (params/estimator.py,
simulators.py, grid.py, with the bounds stated here), the node pages in docs/
show them, and the offline tools read parameter files against the same defaults.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

from estimation_nodes.core.tiles.models import (
    BOOK_CLASSES,
    BOOK_KERNEL,
    BOOK_SENSOR_MODEL,
    BOOK_WORLD,
)

#: Marks a parameter with no default: declared by type, unset means "not given".
UNSET = None


@dataclass(frozen=True)
class ParamSpec:
    """One parameter: name, default (or the type name when it has none), description."""

    name: str
    default: Any
    description: str
    read_only: bool = False
    #: For parameters without a default: one of "string_array", "double_array".
    type_name: str = ""
    #: Inclusive bounds shown by `ros2 param describe` (numbers only).
    min_value: float | None = None
    max_value: float | None = None


WORLD_SPECS = (
    ParamSpec("world", list(BOOK_WORLD),
              "Class name of each cell of the cyclic world, in order (index 0 first)."),
    ParamSpec("world_file", "",
              "Path of a UTF-8 text file with the class name of each cell, separated by white "
              "space; when set it replaces 'world' (for large worlds).", read_only=True),
    ParamSpec("classes", list(BOOK_CLASSES), "Names of the tile classes the sensor reports."),
    ParamSpec("sensor_model", [p for row in BOOK_SENSOR_MODEL for p in row],
              "p(observed class | true class), row-major: one row per true class in the "
              "order of 'classes', one column per observed class; rows sum to 1."),
    ParamSpec("motion_kernel", list(BOOK_KERNEL),
              "Probabilities of landing at offsets -k..k around the commanded target "
              "(odd length, centred, sums to 1)."),
)

#: Bounds on what the Kalman parameters accept. With variances and states within
#: these, no step of the scalar filter can overflow a double before some 1e290
#: steps. A matrix filter can still diverge (an unstable A grows P without
#: bound); every result that would not be finite, from that or from an extreme
#: measurement, is dropped by the filter and counted, and nothing non-finite is
#: ever published.
MAX_STATE = 1e12
MIN_VARIANCE = 1e-12
MAX_VARIANCE = 1e12
_ENTRIES = f" Entries within +-{MAX_STATE:g}."

#: The linear system of the book's Eq. 6.34, for the estimator's matrix mode and for the
#: simulated system (linear_system) alike: one scenario section can serve both.
MATRIX_SPECS = (
    ParamSpec("kalman.matrix.x0", [0.0], "Matrix mode: initial state x0; its length n sets "
              f"the state size.{_ENTRIES}"),
    ParamSpec("kalman.matrix.P0", [100.0],
              f"Matrix mode: initial covariance, n x n row-major.{_ENTRIES}"),
    ParamSpec("kalman.matrix.A", [1.0],
              f"Matrix mode: transition matrix A, n x n row-major.{_ENTRIES}"),
    ParamSpec("kalman.matrix.B", [1.0], "Matrix mode: input matrix B, n x m row-major; m "
              "inputs per kalman_input (m = 1: motion_cmd drives it too)." + _ENTRIES),
    ParamSpec("kalman.matrix.C", [1.0], "Matrix mode: measurement matrix C, p x n row-major; "
              "p values per kalman_measurement (p = 1: position_measurement corrects too)."
              + _ENTRIES),
    ParamSpec("kalman.matrix.F", [1.0],
              f"Matrix mode: noise-input matrix F, n x q row-major.{_ENTRIES}"),
    ParamSpec("kalman.matrix.Q", [2.0],
              f"Matrix mode: process noise covariance, q x q.{_ENTRIES}"),
    ParamSpec("kalman.matrix.R", [4.0],
              f"Matrix mode: measurement noise covariance, p x p.{_ENTRIES}"),
)

ESTIMATOR_SPECS = WORLD_SPECS + MATRIX_SPECS + (
    ParamSpec("initial_belief", UNSET,
              "Prior over the cells (normalized); leave unset for a uniform prior.",
              type_name="double_array"),
    ParamSpec("kalman.mode", "scalar",
              "'scalar': the book's Algorithm 4 with kalman.x0/P0/var_u/var_z; 'matrix': "
              "the matrix filter with kalman.matrix.*.", read_only=True),
    ParamSpec("kalman.x0", 0.0, "Initial position estimate (cells) of the scalar filter.",
              min_value=-MAX_STATE, max_value=MAX_STATE),
    ParamSpec("kalman.P0", 100.0, "Initial variance of the scalar filter.",
              min_value=MIN_VARIANCE, max_value=MAX_VARIANCE),
    ParamSpec("kalman.var_u", 2.0, "Variance of an executed move.",
              min_value=MIN_VARIANCE, max_value=MAX_VARIANCE),
    ParamSpec("kalman.var_z", 4.0, "Variance of a position measurement.",
              min_value=MIN_VARIANCE, max_value=MAX_VARIANCE),
    ParamSpec("kalman.pose_components", [0],
              "The state components shown as pose x, y, z, roll, pitch, yaw of "
              "kalman_estimate (up to 6 indices into the state; -1 for none); the matching "
              "block of P fills the pose covariance."),
    ParamSpec("frame_id", "map", "frame_id of kalman_estimate_stamped (not empty)."),
    ParamSpec("history_depth", 1,
              "How many of the latest estimates each output topic keeps for late subscribers "
              "(transient_local): 1 hands a late `ros2 topic echo` the latest, as /map or "
              "/amcl_pose do; more replays that many, oldest first.", read_only=True,
              min_value=1, max_value=100000),
    ParamSpec("diagnostics_period", 1.0, "Seconds between /diagnostics messages.",
              read_only=True, min_value=0.01, max_value=3600.0),
    ParamSpec("compiled_kernels", False,
              "Worlds of 65,536 cells or more: run the histogram steps as numba-compiled "
              "kernels (less CPU time per step) at the price of the resident memory numba and "
              "LLVM hold and a slower start-up. Off by default: a step through DDS on such a "
              "world is dominated by moving the two belief messages, so the node's end-to-end "
              "rate does not change measurably (figures: docs/benchmarks.md).",
              read_only=True),
    ParamSpec("reorder_horizon", 10.0,
              "Seconds of past events kept so that a late one (a reading that arrived before "
              "the move that caused it, a backlog after a network outage) is applied in the "
              "order the events happened, by their source timestamps, and the events after "
              "it again, republishing their estimates. 0: apply in arrival order.",
              read_only=True, min_value=0.0, max_value=3600.0),
    ParamSpec("reorder_memory_mb", 64.0,
              "Most memory the saved states of the reorder history may take (one belief and "
              "one Kalman state per event): on a large world it bounds how many events are "
              "kept, below reorder_horizon.", read_only=True, min_value=1.0,
              max_value=65536.0),
)


def spec_defaults(specs: tuple[ParamSpec, ...]) -> dict[str, Any]:
    """Every parameter's default, by name (UNSET for those without one)."""
    return {spec.name: spec.default for spec in specs}


#: The simulators' readings wait for these subscribers (hold_until_matched).
HOLD_FOR_NODES = ParamSpec(
    "hold_for_nodes", ["estimator"],
    "Nodes (names relative to this node's namespace, or absolute) whose subscriptions must be "
    "matched before a reading goes out, with hold_until_matched: a recorder or `ros2 topic "
    "echo` that matches first does not let readings go out that the estimator would miss.",
    read_only=True)

SENSOR_SPECS = WORLD_SPECS + (
    ParamSpec("initial_cell", 0, "True starting cell of the robot (index, 0-based).",
              read_only=True),
    ParamSpec("seed", -1, "Seed of the random motion and sensor noise; -1 draws one from the "
              "operating system.", read_only=True),
    ParamSpec("measurement_variance", 4.0,
              "Variance of the Gaussian noise on position_measurement (cells^2).",
              read_only=True, min_value=MIN_VARIANCE, max_value=MAX_VARIANCE),
    ParamSpec("scripted_observations", UNSET,
              "Scripted mode: tile classes to publish, one per command, instead of sampling.",
              read_only=True, type_name="string_array"),
    ParamSpec("scripted_measurements", UNSET,
              "Scripted mode: position measurements to publish, one per command.",
              read_only=True, type_name="double_array"),
    ParamSpec("hold_until_matched", True,
              "Keep readings (up to 1000 per topic) until the nodes of hold_for_nodes (any "
              "subscriber, if it is empty) are matched on their topic and send them, in "
              "order, then: a sensor (re)started before the estimator has discovered it loses "
              "nothing.", read_only=True),
    HOLD_FOR_NODES,
)

COMMANDER_SPECS = (
    ParamSpec("commands", [1], "Motion commands to publish, in cells (positive: index + u).",
              read_only=True),
    ParamSpec("input_vectors", UNSET,
              "When set: publish these as kalman_input (std_msgs/Float64MultiArray), "
              "input_size values per command, row-major, instead of 'commands' on motion_cmd.",
              read_only=True, type_name="double_array"),
    ParamSpec("input_size", 1, "Values per command of input_vectors (m).", read_only=True,
              min_value=1, max_value=1000),
    ParamSpec("rate_hz", 2.0, "Commands per second.", read_only=True,
              min_value=0.001, max_value=100000.0),
    ParamSpec("repeat", False, "Start the sequence again after its last command.",
              read_only=True),
    ParamSpec("max_commands", 0, "Stop after this many commands in all (0: no limit).",
              read_only=True, min_value=0, max_value=2**31 - 1),
    ParamSpec("required_subscribers", 2, "Matched subscriptions on motion_cmd to wait for "
              "before the first command (0: send without waiting for anyone).",
              read_only=True, min_value=0, max_value=1000),
    ParamSpec("required_nodes", UNSET,
              "Nodes (names relative to this node's namespace, or absolute) that must be "
              "matched subscribers before a command goes out, beside required_subscribers; "
              "unset: estimator and tile_sensor (estimator and linear_system with "
              "input_vectors). A recorder or `ros2 topic echo` counts as a subscriber but "
              "never stands in for one of these.", read_only=True, type_name="string_array"),
    ParamSpec("start_delay", 1.0, "Seconds to wait after the subscribers are there, so the "
              "rest of the graph can discover itself.", read_only=True,
              min_value=0.0, max_value=3600.0),
    ParamSpec("exit_when_done", False, "End the process after the last command instead of "
              "staying up.", read_only=True),
)

#: The simulated system runs one model from start to end: its matrices are read-only.
LINEAR_SYSTEM_SPECS = tuple(replace(spec, read_only=True) for spec in MATRIX_SPECS) + (
    ParamSpec("true_initial_state", UNSET,
              "The simulated system's true initial state; unset: kalman.matrix.x0.",
              read_only=True, type_name="double_array"),
    ParamSpec("seed", -1, "Seed of the process and measurement noise; -1 draws one from the "
              "operating system.", read_only=True),
    ParamSpec("hold_until_matched", True,
              "Keep measurements (up to 1000) until the nodes of hold_for_nodes are matched "
              "on kalman_measurement and send them, in order, then.", read_only=True),
    HOLD_FOR_NODES,
)

#: Where a Foxglove live view listens unless told: this machine only, Foxglove's usual port.
FOXGLOVE_HOST = "127.0.0.1"
FOXGLOVE_PORT = 8765

FOXGLOVE_VIEW_SPECS = (
    ParamSpec("host", FOXGLOVE_HOST, "Address the Foxglove WebSocket server listens on: "
              "127.0.0.1 for this machine only, 0.0.0.0 for every interface, or a host name.",
              read_only=True),
    ParamSpec("port", FOXGLOVE_PORT, "TCP port of the Foxglove WebSocket server (0: any free "
              "port, logged at start).", read_only=True, min_value=0, max_value=65535),
)

#: The likelihood field and the odometry noise, shared by the localizer and the simulated
#: robot: the simulator draws its noise from the model the localizer assumes.
GRID_MODEL_SPECS = (
    ParamSpec("map_file", "", "A map in map_server's format (YAML with image, resolution, "
              "origin, negate, occupied_thresh, free_thresh, mode); empty: the localizer "
              "takes the map from the map topic.", read_only=True),
    ParamSpec("laser_z_hit", 0.5, "Weight of the Gaussian around the nearest obstacle in the "
              "likelihood field (AMCL's laser_z_hit).", read_only=True, min_value=0.0,
              max_value=1.0),
    ParamSpec("laser_z_rand", 0.5, "Weight of random readings, uniform over the range "
              "(AMCL's laser_z_rand); must be > 0 so no scan rules out every state.",
              read_only=True, min_value=1e-6, max_value=1.0),
    ParamSpec("laser_sigma_hit", 0.2, "Std (m) of a reading around the nearest obstacle.",
              read_only=True, min_value=0.001, max_value=10.0),
    ParamSpec("laser_max_range", 12.0, "Readings at or beyond this (m) are no return.",
              read_only=True, min_value=0.1, max_value=1000.0),
    ParamSpec("laser_likelihood_max_dist", 2.0, "Distances to obstacles are capped at this "
              "(m) in the likelihood field.", read_only=True, min_value=0.01, max_value=100.0),
    ParamSpec("laser_pose", [0.0, 0.0, 0.0], "[x, y, yaw] of the laser on the robot (m, m, "
              "rad; base_link -> laser frame): each beam starts there.", read_only=True),
    ParamSpec("alpha1", 0.2, "Rotation noise from rotation (AMCL's alpha1).", read_only=True,
              min_value=0.0, max_value=10.0),
    ParamSpec("alpha2", 0.2, "Rotation noise from translation (rad per m).", read_only=True,
              min_value=0.0, max_value=10.0),
    ParamSpec("alpha3", 0.2, "Translation noise from translation.", read_only=True,
              min_value=0.0, max_value=10.0),
    ParamSpec("alpha4", 0.2, "Translation noise from rotation (m per rad).", read_only=True,
              min_value=0.0, max_value=10.0),
)

#: The localizer's mount is taken from the tf tree unless laser_pose is given (an override).
_LOCALIZER_MODEL_SPECS = tuple(
    ParamSpec("laser_pose", UNSET, "[x, y, yaw] of the laser on the robot (m, m, rad; "
              "base_frame_id -> the scan's frame): an override of the mount. Unset: with "
              "odometry_source tf, the tree's transform from base_frame_id to the scan's "
              "frame_id (/tf_static, as AMCL takes it); with odometry_source topic, "
              "[0, 0, 0].", read_only=True, type_name="double_array")
    if spec.name == "laser_pose" else spec for spec in GRID_MODEL_SPECS)

#: nav2_amcl's names where the meaning is the same (docs/nodes/grid_localizer.md compares).
GRID_TF_SPECS = (
    ParamSpec("odometry_source", "tf", "Where odometry comes from: 'tf' (odom_frame_id -> "
              "base_frame_id on /tf at each scan's time, as AMCL takes it) or 'topic' "
              "(nav_msgs/Odometry on odom, as the package's simulator publishes it).",
              read_only=True),
    ParamSpec("odom_frame_id", "odom", "The odometry's frame (AMCL's odom_frame_id).",
              read_only=True),
    ParamSpec("base_frame_id", "base_link", "The robot's frame (AMCL's base_frame_id).",
              read_only=True),
    ParamSpec("global_frame_id", "map", "The map's frame: of the published pose, belief and "
              "map -> odom (AMCL's global_frame_id).", read_only=True),
    ParamSpec("tf_broadcast", True, "Publish global_frame_id -> odom_frame_id on /tf after "
              "each scan, so that the tree gives map -> base_link (AMCL's tf_broadcast).",
              read_only=True),
    ParamSpec("transform_tolerance", 1.0, "map -> odom is stamped this long (s) after its "
              "scan's time, so that lookups of the latest time succeed until the next scan "
              "(AMCL's transform_tolerance); with odometry_source tf a scan also waits at most "
              "this long for its transforms, then is dropped and counted.", read_only=True,
              min_value=0.0, max_value=60.0),
    ParamSpec("autostart", False, "Configure and activate at start, for running alone; "
              "false: wait, unconfigured, for a lifecycle manager (Nav2's) to do it.",
              read_only=True),
    ParamSpec("set_initial_pose", False, "Take initial_pose.x, .y, .yaw as the prior at "
              "start (AMCL's set_initial_pose; its covariance: 0.5 m, 0.5 m, 15 degrees std).",
              read_only=True),
    ParamSpec("initial_pose.x", 0.0, "Initial pose's x (m) when set_initial_pose.",
              read_only=True, min_value=-1e6, max_value=1e6),
    ParamSpec("initial_pose.y", 0.0, "Initial pose's y (m) when set_initial_pose.",
              read_only=True, min_value=-1e6, max_value=1e6),
    ParamSpec("initial_pose.yaw", 0.0, "Initial pose's yaw (rad) when set_initial_pose.",
              read_only=True, min_value=-10.0, max_value=10.0),
)

GRID_LOCALIZER_SPECS = _LOCALIZER_MODEL_SPECS + GRID_TF_SPECS + (
    ParamSpec("resolution", 0.1, "Size (m) of a state cell: a whole multiple of the map's "
              "resolution; the map is reduced to it.", read_only=True, min_value=0.001,
              max_value=100.0),
    ParamSpec("heading_bins", 72, "Heading bins of the state grid (72: 5 degrees).",
              read_only=True, min_value=1, max_value=3600),
    ParamSpec("max_states", 5_000_000, "A map with more states (cells x headings) is refused.",
              read_only=True, min_value=1, max_value=200_000_000),
    ParamSpec("max_beams", 60, "Beams of a scan used, evenly chosen among the valid ones.",
              read_only=True, min_value=1, max_value=10000),
    ParamSpec("laser_independent_beams", 40, "A scan corrects the belief as this many "
              "independent beams: with more beams used, the log likelihood of the scan is "
              "scaled by this number over theirs (a tempered likelihood), since neighbouring "
              "beams' errors are correlated; max_beams or more: every beam independent.",
              read_only=True, min_value=1, max_value=10000),
    ParamSpec("update_min_d", 0.25, "Translation (m) that triggers a filter update.",
              read_only=True, min_value=0.0, max_value=100.0),
    ParamSpec("update_min_a", 0.2, "Rotation (rad) that triggers a filter update.",
              read_only=True, min_value=0.0, max_value=10.0),
    ParamSpec("kidnap_probability", 1e-6, "Probability per update that the robot was "
              "carried anywhere: that much of the belief is spread uniformly over the free "
              "cells before each correction, so a kidnapped robot is found again by its scans "
              "alone (0: the exact filter; ~/global_localization recovers).", read_only=True,
              min_value=0.0, max_value=0.5),
    ParamSpec("odometry_failure_probability", 0.25, "Probability per update that the "
              "odometry failed since the last one (wheels slipping, an encoder running "
              "backwards) and the robot is anywhere within 8 m of the predicted pose or of the "
              "last update's, nearer the likelier: a mixture component whose posterior lowers "
              "localization_quality and widens the covariance when a place around explains "
              "the scan better than the tracked belief; the pose is the tracked belief's. "
              "0: left out (needs belief_floor > 0 and kidnap_probability > 0, whose lattice "
              "it is scored on).", read_only=True, min_value=0.0, max_value=0.9),
    ParamSpec("belief_floor", 1e-9, "After each correction the states of less probability "
              "than this are dropped (at most this x the states per update, reported in "
              "/diagnostics) and the filter runs over the box of those left, grown by what "
              "the motion reaches: a tracked robot costs its few square metres, not the "
              "building. 0: the dense filter over every state.", read_only=True,
              min_value=0.0, max_value=1e-3),
    ParamSpec("scan_fit", True, "Publish the pose where the last scan fits the map best "
              "on the map's own resolution, within a state cell and a heading bin of the "
              "belief's mean (a local scan match; the belief, its covariance and the quality "
              "stay the filter's). false: the belief's mean around its most likely state.",
              read_only=True),
    ParamSpec("max_odom_jump", 1.0, "An odometry step longer than this (m) is a jump: "
              "dropped, counted, and the odometry followed from the new pose.",
              read_only=True, min_value=0.01, max_value=1000.0),
    ParamSpec("odom_wait", 1.0, "Seconds a scan waits for the odometry of its time (as "
              "tf's message filter waits for a transform), then dropped and counted; scans "
              "that come meanwhile wait behind it, in order (10 at most). More than the "
              "odometry's period: a real log's comes at 2 Hz in places.",
              read_only=True, min_value=0.01, max_value=60.0),
    ParamSpec("quality_radius", 0.3, "localization_quality: the belief's probability within "
              "this distance (m) of the published pose ...", read_only=True, min_value=0.0,
              max_value=100.0),
    ParamSpec("quality_angle", 10.0, "... and this heading difference (degrees).",
              read_only=True, min_value=0.0, max_value=180.0),
    ParamSpec("history_depth", 1,
              "How many of the latest outputs pose, belief_map and localization_quality each "
              "keep for late subscribers (transient_local): 1 hands a late `ros2 topic echo` "
              "the latest, as /amcl_pose does; more replays that many, oldest first, so a "
              "recorder that hears the localizer late still records its first updates.",
              read_only=True, min_value=1, max_value=100000),
    ParamSpec("diagnostics_period", 1.0, "Seconds between /diagnostics messages.",
              read_only=True, min_value=0.01, max_value=3600.0),
)

PLANAR_ROBOT_SPECS = GRID_MODEL_SPECS + (
    ParamSpec("seed", -1, "Seed of the route, the odometry and the scan noise; -1 draws "
              "one from the operating system.", read_only=True),
    ParamSpec("rate_hz", 10.0, "Simulation steps (odometry and scans) per second.",
              read_only=True, min_value=0.1, max_value=1000.0),
    ParamSpec("speed", 0.5, "Forward speed (m/s) when wandering.", read_only=True,
              min_value=0.0, max_value=10.0),
    ParamSpec("turn_rate", 1.0, "Rotation speed (rad/s) when turning away from an obstacle.",
              read_only=True, min_value=0.01, max_value=20.0),
    ParamSpec("robot_radius", 0.25, "The robot keeps this far (m) from every obstacle.",
              read_only=True, min_value=0.0, max_value=10.0),
    ParamSpec("beams", 180, "Beams of the simulated scan, over a full turn.", read_only=True,
              min_value=1, max_value=10000),
    ParamSpec("scan_noise_std", 0.05, "Std (m) of the Gaussian noise on each simulated range "
              "(the likelihood field's hit model; the localizer's laser_sigma_hit is wider, as "
              "AMCL's is, to be robust).", read_only=True, min_value=0.0, max_value=10.0),
    ParamSpec("scan_random_fraction", 0.05, "Fraction of simulated readings that are random, "
              "uniform over the range (the likelihood field's z_rand part).", read_only=True,
              min_value=0.0, max_value=1.0),
    ParamSpec("initial_pose", UNSET, "[x, y, yaw] where the robot starts; unset: a free place "
              "drawn from the seed.", read_only=True, type_name="double_array"),
    ParamSpec("duration", 0.0, "Stop after this many seconds of simulated motion (0: never); "
              "with exit_when_done the process ends then.", read_only=True, min_value=0.0,
              max_value=1e6),
    ParamSpec("exit_when_done", False, "End the process when duration is over.",
              read_only=True),
    ParamSpec("kidnap_after", 0.0, "Teleport the robot to another free place after this many "
              "seconds (0: never), to see the localizer lose and find it again.",
              read_only=True, min_value=0.0, max_value=1e6),
    ParamSpec("hold_until_matched", True,
              "Start moving (the first odom and scan) only once the nodes of hold_for_nodes "
              "(any subscriber, if it is empty) are matched on odom and scan: a localizer or "
              "a recorder started with the robot misses none of its run.", read_only=True),
    replace(HOLD_FOR_NODES, default=["grid_localizer"], description=(
        "Nodes (names relative to this node's namespace, or absolute) whose subscriptions "
        "to odom and scan must be matched before the robot starts, with hold_until_matched; "
        "add a recorder's node to have it record the whole run (a count of subscribers "
        "would let `ros2 topic echo` stand in for the localizer).")),
)

#: The landmark filter (ekf_localizer): the unicycle's odometry noise, the camera's
#: range-bearing noise and mounting, the gate and its recovery, the UKF's sigma points.
LANDMARK_MODEL_SPECS = (
    ParamSpec("filter", "ekf", "'ekf': the extended Kalman filter (models linearized at the "
              "estimate); 'ukf': the unscented one (Van der Merwe's sigma points).",
              read_only=True),
    ParamSpec("noise.translation_per_m", 4e-4, "Variance (m^2) of the distance a step "
              "travelled, per metre travelled.", min_value=0.0, max_value=100.0),
    ParamSpec("noise.translation_per_rad", 3e-3, "Variance (m^2) of the distance a step "
              "travelled, per radian turned.", min_value=0.0, max_value=100.0),
    ParamSpec("noise.translation_per_s", 1e-6, "Variance (m^2) of the distance a step "
              "travelled, per second (a robot standing still slips a little).",
              min_value=0.0, max_value=100.0),
    ParamSpec("noise.rotation_per_m", 1e-4, "Variance (rad^2) of the turn of a step, per "
              "metre travelled.", min_value=0.0, max_value=100.0),
    ParamSpec("noise.rotation_per_rad", 1.2e-2, "Variance (rad^2) of the turn of a step, per "
              "radian turned.", min_value=0.0, max_value=100.0),
    ParamSpec("noise.rotation_per_s", 1.2e-3, "Variance (rad^2) of the turn of a step, per "
              "second.", min_value=0.0, max_value=100.0),
    ParamSpec("range_std", 0.01, "Std (m) of a landmark's measured range, besides "
              "range_std_per_m.", min_value=1e-6, max_value=100.0),
    ParamSpec("range_std_per_m", 0.04, "Std of a measured range that grows with the range "
              "(m per m): the std is range_std + range_std_per_m * range.", min_value=0.0,
              max_value=10.0),
    ParamSpec("bearing_std", 0.027, "Std (rad) of a landmark's measured bearing.",
              min_value=1e-6, max_value=3.2),
    ParamSpec("range_model", "euclidean", "What the sensor's range measures: 'euclidean' "
              "(the distance to the landmark) or 'depth' (its distance along the sensor's "
              "axis, range cos(bearing), as a camera that ranges by apparent size reports)."),
    ParamSpec("range_scale", 1.0, "The sensor reports this many times the true range (a "
              "calibration; 1 for a calibrated sensor).", min_value=0.5, max_value=2.0),
    ParamSpec("range_scale_std", 0.0, "Estimate the range's scale with the pose, from a "
              "prior of range_scale with this std (a fourth state; 0: range_scale is taken "
              "as exact). For a camera whose scale is known to a few percent only; an "
              "initialpose or ~/reset starts it again from that prior.",
              read_only=True, min_value=0.0, max_value=0.25),
    ParamSpec("odometry_delay", 0.0, "Seconds between an odometry message's stamp and the "
              "robot driving its twist (0 for measured speeds; a robot that reports its "
              "commands follows them late).", read_only=True, min_value=0.0, max_value=10.0),
    ParamSpec("odometry_scale", [1.0, 1.0], "[forward, turn]: the speeds the robot drives "
              "per unit of the speeds its odometry reports (1 for measured speeds; each in "
              "(0, 10]).",
              type_name="double_array"),
    ParamSpec("sensor_pose", [0.0, 0.0, 0.0], "[x, y, yaw] of the camera on the robot (m, m, "
              "rad from the robot's heading)."),
    ParamSpec("sensor_pose_std", [0.0, 0.0, 0.0], "[x, y, yaw] std of sensor_pose (m, m, "
              "rad; each in [0, 1]): how well the mount is known, e.g. the spread of a "
              "fleet's calibrations. The filter takes sensor_pose as exact; the published "
              "covariance adds the pose error a mount error makes.",
              type_name="double_array"),
    ParamSpec("gate_probability", 0.999, "An observation whose innovation lies outside this "
              "probability's Mahalanobis ellipse is counted and skipped (1: no gate).",
              min_value=0.5, max_value=1.0),
    ParamSpec("recovery_time", 5.0, "After this many seconds with every observation gated, "
              "the filter is lost: a frame of two landmarks or more that fit one pose "
              "places it there; else the covariance grows by recovery_std and the gate "
              "judges again.",
              min_value=0.01, max_value=3600.0),
    ParamSpec("recovery_std", [1.0, 0.5], "[position (m), heading (rad)]: the std a recovery "
              "adds to the covariance (the filter admits it no longer knows where it is).",
              type_name="double_array"),
    ParamSpec("ekf.iterations", 1, "Passes of the EKF's correction, each linearized at the "
              "last pass's estimate (1: the EKF; more: the iterated EKF, which keeps a "
              "landmark's bearing from pulling a very uncertain heading astray).",
              min_value=1, max_value=100),
    ParamSpec("ukf.alpha", 0.5, "The UKF's sigma-point spread (0 < alpha <= 1).",
              read_only=True, min_value=1e-4, max_value=1.0),
    ParamSpec("ukf.beta", 2.0, "The UKF's prior-knowledge weight (2: optimal for a Gaussian).",
              read_only=True, min_value=0.0, max_value=10.0),
    ParamSpec("ukf.kappa", 0.0, "The UKF's secondary scaling (0, or 3 - n).", read_only=True,
              min_value=-2.9, max_value=100.0),
)


EKF_LOCALIZER_SPECS = LANDMARK_MODEL_SPECS + (
    ParamSpec("landmarks_file", "", "YAML with the landmarks: `landmarks: [{id: 6, x: 0.588, "
              "y: -4.282}, ...]`, metres in the map frame.", read_only=True),
    ParamSpec("initial_pose", [0.0, 0.0, 0.0], "[x, y, yaw] the filter starts from (m, m, "
              "rad, map frame)."),
    ParamSpec("initial_covariance", [1.0, 1.0, 0.25], "Variances of x, y and yaw it starts "
              "with (m^2, m^2, rad^2): 3 values (a diagonal) or 9 (row-major)."),
    ParamSpec("frame_id", "map", "Frame of the published pose and of map -> odom."),
    ParamSpec("autostart", False, "Configure and activate at start, for running alone; "
              "false: wait, unconfigured, for a lifecycle manager (Nav2's) to do it.",
              read_only=True),
    ParamSpec("odom_frame_id", "odom", "The frame of the odometry's poses (its header's).",
              read_only=True),
    ParamSpec("tf_broadcast", True, "Publish frame_id -> odom_frame_id on /tf after each "
              "odometry message: the estimate composed with the inverse of that message's "
              "pose, so the tree's map -> base_link is the estimate.", read_only=True),
    ParamSpec("transform_tolerance", 0.1, "map -> odom is stamped this long (s) after its "
              "odometry's time (AMCL's transform_tolerance).", read_only=True,
              min_value=0.0, max_value=60.0),
    ParamSpec("reorder_horizon", 2.0, "Seconds of events kept to apply a late one in its "
              "place (odometry and camera frames come on two topics).", read_only=True,
              min_value=0.0, max_value=3600.0),
    ParamSpec("history_depth", 1,
              "How many of the latest poses pose keeps for late subscribers "
              "(transient_local): 1 hands a late `ros2 topic echo` the latest, as /amcl_pose "
              "does; more replays that many, oldest first, and lets a busy subscriber catch "
              "up without losing one.", read_only=True, min_value=1, max_value=100000),
    ParamSpec("diagnostics_period", 1.0, "Seconds between /diagnostics messages.",
              read_only=True, min_value=0.01, max_value=3600.0),
)

#: The simulated robot among landmarks: its noise and its camera use the landmark
#: filter's parameter names, so one parameter file gives both the same models.
LANDMARK_ROBOT_SPECS = tuple(
    spec for spec in LANDMARK_MODEL_SPECS if spec.name.startswith("noise.")
    or spec.name in ("range_std", "range_std_per_m", "bearing_std", "sensor_pose")) + (
    ParamSpec("landmarks_file", "", "YAML with the landmarks: `landmarks: [{id: 6, x: 0.588, "
              "y: -4.282}, ...]`, metres in the map frame.", read_only=True),
    ParamSpec("seed", -1, "Seed of the route and of every noise; -1 draws one from the "
              "operating system.", read_only=True),
    ParamSpec("rate_hz", 50.0, "Odometry messages per second (each a simulation step).",
              read_only=True, min_value=0.1, max_value=1000.0),
    ParamSpec("camera_rate_hz", 5.0, "Camera frames per second.", read_only=True,
              min_value=0.01, max_value=1000.0),
    ParamSpec("camera_max_range", 6.0, "The camera sees landmarks up to this range (m).",
              read_only=True, min_value=0.01, max_value=1000.0),
    ParamSpec("camera_field_of_view", 1.0, "...and within this angle (rad) about its axis.",
              read_only=True, min_value=0.01, max_value=6.3),
    ParamSpec("speed", 0.3, "The fastest forward speed (m/s) the route commands.",
              read_only=True, min_value=0.0, max_value=10.0),
    ParamSpec("turn_rate", 0.6, "The fastest turn rate (rad/s) the route commands.",
              read_only=True, min_value=0.0, max_value=20.0),
    ParamSpec("initial_pose", [0.0, 0.0, 0.0], "[x, y, yaw] where the robot starts.",
              read_only=True),
    ParamSpec("duration", 0.0, "Stop after this many seconds of simulated motion (0: never); "
              "with exit_when_done the process ends then.", read_only=True, min_value=0.0,
              max_value=1e6),
    ParamSpec("exit_when_done", False, "End the process when duration is over.",
              read_only=True),
    ParamSpec("hold_until_matched", True,
              "Start moving (the first odom and camera frame) only once the nodes of "
              "hold_for_nodes (any subscriber, if it is empty) are matched on odom and "
              "landmark_observations: a localizer or a recorder started with the robot misses "
              "none of its run.", read_only=True),
    replace(HOLD_FOR_NODES, default=["ekf_localizer"], description=(
        "Nodes (names relative to this node's namespace, or absolute) whose subscriptions "
        "to odom and landmark_observations must be matched before the robot starts, with "
        "hold_until_matched; add a recorder's node to have it record the whole run.")),
)

#: Each node's parameters, by node name.
NODE_SPECS: dict[str, tuple[ParamSpec, ...]] = {
    "estimator": ESTIMATOR_SPECS,
    "tile_sensor": SENSOR_SPECS,
    "motion_commander": COMMANDER_SPECS,
    "linear_system": LINEAR_SYSTEM_SPECS,
    "foxglove_view": FOXGLOVE_VIEW_SPECS,
    "grid_localizer": GRID_LOCALIZER_SPECS,
    "planar_robot": PLANAR_ROBOT_SPECS,
    "ekf_localizer": EKF_LOCALIZER_SPECS,
    "landmark_robot": LANDMARK_ROBOT_SPECS,
}


def spec_named(name: str, specs: tuple[ParamSpec, ...] | None = None) -> ParamSpec:
    """Parameter ``name``'s spec: from ``specs`` when given (a node's own, for a name two
    nodes use differently, such as rate_hz), else from whichever node declares it."""
    for candidate in specs or (spec for table in NODE_SPECS.values() for spec in table):
        if candidate.name == name:
            return candidate
    raise KeyError(name)
