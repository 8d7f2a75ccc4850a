"""Bayes and Kalman state estimation as ROS 2 nodes.

The maths lives in :mod:`estimation_nodes.core` (numpy only); the nodes in
:mod:`estimation_nodes.nodes` are thin rclpy wrappers around it.
"""
