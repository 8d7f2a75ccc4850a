"""The graph's topics: names (relative, so namespaces and remaps apply) and ROS types.

The nodes publish and subscribe these; the demo's monitor, the recorder and
the replay read them by the same names.
"""

from __future__ import annotations

MOTION_CMD = "motion_cmd"
TILE_OBSERVATION = "tile_observation"
POSITION_MEASUREMENT = "position_measurement"
TRUE_POSITION = "true_position"
BELIEF_PREDICTED = "belief_predicted"
BELIEF = "belief"
KALMAN_ESTIMATE = "kalman_estimate"
KALMAN_ESTIMATE_STAMPED = "kalman_estimate_stamped"
KALMAN_ESTIMATE_PREDICTED = "kalman_estimate_predicted"
KALMAN_ESTIMATE_PREDICTED_STAMPED = "kalman_estimate_predicted_stamped"
KALMAN_INPUT = "kalman_input"
KALMAN_MEASUREMENT = "kalman_measurement"
TRUE_STATE = "true_state"
KALMAN_STATE = "kalman_state"
KALMAN_STATE_PREDICTED = "kalman_state_predicted"

#: What drives the estimator, in the order it subscribes (commands first).
INPUTS = (MOTION_CMD, TILE_OBSERVATION, POSITION_MEASUREMENT, KALMAN_INPUT, KALMAN_MEASUREMENT)

#: Every topic of a run: relative name -> ROS type.
TOPIC_TYPES = {
    MOTION_CMD: "std_msgs/msg/Int32",
    TILE_OBSERVATION: "std_msgs/msg/String",
    POSITION_MEASUREMENT: "std_msgs/msg/Float64",
    TRUE_POSITION: "std_msgs/msg/Int64",
    BELIEF_PREDICTED: "std_msgs/msg/Float64MultiArray",
    BELIEF: "std_msgs/msg/Float64MultiArray",
    KALMAN_ESTIMATE: "geometry_msgs/msg/PoseWithCovariance",
    KALMAN_ESTIMATE_STAMPED: "geometry_msgs/msg/PoseWithCovarianceStamped",
    KALMAN_ESTIMATE_PREDICTED: "geometry_msgs/msg/PoseWithCovariance",
    KALMAN_ESTIMATE_PREDICTED_STAMPED: "geometry_msgs/msg/PoseWithCovarianceStamped",
    KALMAN_INPUT: "std_msgs/msg/Float64MultiArray",
    KALMAN_MEASUREMENT: "std_msgs/msg/Float64MultiArray",
    TRUE_STATE: "std_msgs/msg/Float64MultiArray",
    KALMAN_STATE: "std_msgs/msg/Float64MultiArray",
    KALMAN_STATE_PREDICTED: "std_msgs/msg/Float64MultiArray",
}

#: The estimator's health, on the absolute name ROS's diagnostic tools read. Not in
#: TOPIC_TYPES: a run's record and replay have no use for it; a live view shows it.
DIAGNOSTICS = "/diagnostics"

#: What a live view (Foxglove) serves: every topic of a run, and the diagnostics.
LIVE_TOPIC_TYPES = {**TOPIC_TYPES, DIAGNOSTICS: "diagnostic_msgs/msg/DiagnosticArray"}

#: What each node publishes: the demo waits for the monitor to hear each of them.
ESTIMATOR_OUTPUTS = (BELIEF_PREDICTED, BELIEF, KALMAN_ESTIMATE, KALMAN_ESTIMATE_STAMPED,
                     KALMAN_ESTIMATE_PREDICTED, KALMAN_ESTIMATE_PREDICTED_STAMPED,
                     KALMAN_STATE, KALMAN_STATE_PREDICTED)
SIMULATOR_OUTPUTS = {
    "tile_sensor": (TRUE_POSITION, TILE_OBSERVATION, POSITION_MEASUREMENT),
    "linear_system": (TRUE_STATE, KALMAN_MEASUREMENT),
}

# Grid localization on a map (grid_localizer, planar_robot): the names nav2 uses.
MAP = "map"
SCAN = "scan"
ODOM = "odom"
INITIAL_POSE = "initialpose"
POSE = "pose"
BELIEF_MAP = "belief_map"
LOCALIZATION_QUALITY = "localization_quality"
#: The belief's most likely states as a geometry_msgs/PoseArray (AMCL's particle_cloud).
PARTICLE_CLOUD = "particle_cloud"
TRUE_POSE = "true_pose"
CMD_VEL = "cmd_vel"
LANDMARK_OBSERVATIONS = "landmark_observations"

#: Every topic of a grid localization run: relative name -> ROS type.
GRID_TOPIC_TYPES = {
    MAP: "nav_msgs/msg/OccupancyGrid",
    SCAN: "sensor_msgs/msg/LaserScan",
    ODOM: "nav_msgs/msg/Odometry",
    TRUE_POSE: "geometry_msgs/msg/PoseStamped",
    POSE: "geometry_msgs/msg/PoseWithCovarianceStamped",
    BELIEF_MAP: "nav_msgs/msg/OccupancyGrid",
    LOCALIZATION_QUALITY: "std_msgs/msg/Float64",
}

#: The landmark localization run's topics (ekf_localizer, landmark_robot).
LANDMARK_TOPIC_TYPES = {
    ODOM: "nav_msgs/msg/Odometry",
    LANDMARK_OBSERVATIONS: "sensor_msgs/msg/PointCloud2",
    TRUE_POSE: "geometry_msgs/msg/PoseStamped",
    POSE: "geometry_msgs/msg/PoseWithCovarianceStamped",
}
