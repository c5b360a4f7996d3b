"""Runs: the run directory (layout, save, load) and the lifecycle of one experiment (train,
evaluate, write)."""
