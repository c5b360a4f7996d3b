"""Sweeps on Ray Tune: many configurations and seeds, locally or on a cluster.

    spec = load_sweep("configs/sweeps/hybrid_D2.toml")
    results, summary = run_sweep(spec, "sweeps/hybrid_D2", workers=2)        # a local Ray
    results, summary = run_sweep(spec, "sweeps/hybrid_D2", address="10.0.0.5:6379")

Each trial is an ordinary run directory, trained on any node and verified into the output
by the driver (`sysid.sweep.inbox`); the objective is the validation loss, reported to Tune
after every epoch.
"""
from sysid.sweep.results import SweepResults
from sysid.sweep.spec import Axis, SweepSpec, load_sweep, parse_sweep
from sysid.sweep.study import run_sweep

__all__ = ["Axis", "SweepResults", "SweepSpec", "load_sweep", "parse_sweep", "run_sweep"]
