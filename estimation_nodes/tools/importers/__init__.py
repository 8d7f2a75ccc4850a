"""estimation_import: real robots' logs (CARMEN laser logs, the UTIAS landmark dataset) read as
they are published, and written as ROS 2 recordings."""
