"""Odometry + IMU fusion with robot_localization's 15-state model (no rclpy).

``state``: the state's layout, angle wrapping and the rotations (tf2's conventions);
``motion``: the constant-acceleration omnidirectional motion model and its Jacobian;
``steps``: the EKF and UKF predict and correct steps; ``inputs``: sensor readings turned
into measurements in the robot's frame; ``filter``: the filter as robot_localization's
node runs it (initialization from the first measurement, a periodic update that takes
the queued measurements in time order, prediction after a sensor timeout).
"""
