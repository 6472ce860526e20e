"""Synthetic RGB-D scenes of glassware on a table, with full ground truth (tests, bench, samples)."""
