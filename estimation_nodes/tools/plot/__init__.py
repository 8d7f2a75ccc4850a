"""estimation_plot: pictures of recorded runs."""
