"""``ukf_node``: robot_localization's UKF node (nodes/fusion_node.py)."""

from estimation_nodes.nodes.fusion_node import ukf_main as main

__all__ = ["main"]
