"""What runs outside the graph's nodes: the entry script (demo), its monitor, recording
to MCAP, offline replay and plots."""
