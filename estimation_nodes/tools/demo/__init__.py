"""estimation_demo: runs a scenario's graph, watches it, summarizes it."""
