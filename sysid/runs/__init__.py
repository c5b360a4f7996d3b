"""Runs: the run directory (layout, save, load) and the lifecycle of one experiment (train,
evaluate, write). `RunDir`, the reader of a run directory, loads neither torch nor training code."""
from sysid.runs.rundir import RunDir

__all__ = ["RunDir"]
