"""Grid (Markov) localization over (x, y, heading) on an occupancy map."""
