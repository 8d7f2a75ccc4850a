"""``ekf_node``: robot_localization's EKF node (nodes/fusion_node.py)."""

from estimation_nodes.nodes.fusion_node import ekf_main as main

__all__ = ["main"]
