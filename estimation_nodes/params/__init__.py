"""Configuration without rclpy: parameter specs, builders to core models, parameter files,
and the graph's topic names.

specs: every node's parameters in one table; builders: values -> validated core
models; files: parameter files checked and read as rcl reads them; topics: the
topics' names and types.
"""
