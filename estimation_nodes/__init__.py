"""Bayes, Kalman and grid-localization state estimation as ROS 2 nodes.

The maths lives in :mod:`estimation_nodes.core` (numpy, numba, scipy; no rclpy);
:mod:`estimation_nodes.params` turns parameters into its models; the nodes in
:mod:`estimation_nodes.nodes` are thin rclpy wrappers around it; the tools in
:mod:`estimation_nodes.tools` run outside the graph. docs/architecture.md has the map.
"""
