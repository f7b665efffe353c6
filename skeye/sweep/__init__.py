"""Parameter sweeps: many trials of an experiment on a local pool or a Ray cluster."""
