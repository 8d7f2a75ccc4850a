"""estimation_replay: a recorded run recomputed offline and compared with what was published."""
