"""Configuration without rclpy: the parameter spec table, settings for each node family,
parameter and map files, and the graph's topic names.

specs: every node's parameters in one table; estimator, simulators, grid: values ->
validated settings and core models, per node family (models, values: what they share);
param_files: parameter files checked and read as rcl reads them; map_files: map_server's
maps; topics: the topics' names and types; installed: where the package's files are.
"""
