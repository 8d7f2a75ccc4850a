"""What runs outside the graph's nodes, a package per tool: the demo, recording to MCAP,
offline replay, plots, the Foxglove live view; and param_docs, the node pages' tables."""
