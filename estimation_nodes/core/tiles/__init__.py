"""The book's histogram (discrete Bayes) filter over a cyclic world of tiles."""
