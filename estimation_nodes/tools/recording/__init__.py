"""Runs as MCAP recordings: writing, reading, and the record of a run."""
