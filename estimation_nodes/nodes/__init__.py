"""Thin rclpy nodes over the core: parameters, QoS and message conversion only."""
