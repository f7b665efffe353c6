"""Validation: the paper's experiments, run through the real processes."""
