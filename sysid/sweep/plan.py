"""A sweep's trials: every configuration (grid point or random draw) with every seed, each
with a stable run-directory path ``trials/{point}/seed{k}``."""
from __future__ import annotations

from typing import Any

from sysid.sweep.points import point_name, sweep_points
from sysid.sweep.spec import SweepSpec
from sysid.sweep.trial import TrialSpec

TRIALS_DIR = "trials"


def make_trial(spec: SweepSpec, values: dict[str, Any], seed: int) -> TrialSpec:
    """One configuration and seed; one torch thread unless the sweep varies the threads."""
    point = point_name(values)
    exp = spec.experiment(values, seed, f"{spec.name}-{point}-seed{seed}")
    if "training.threads" not in values:
        exp = exp.replace(training={"threads": 1})
    return TrialSpec(f"{TRIALS_DIR}/{point}/seed{seed}", point, int(seed), exp.to_toml(), dict(values))


def sweep_trials(spec: SweepSpec) -> list[TrialSpec]:
    """Grid or random sweeps: every point x seed, points in order, seeds inside."""
    trials = [make_trial(spec, values, seed) for values in sweep_points(spec) for seed in spec.seeds]
    paths = [t.path for t in trials]
    if len(set(paths)) != len(paths):  # a random search that drew the same point twice
        seen, unique = set(), []
        for t in trials:
            if t.path not in seen:
                seen.add(t.path)
                unique.append(t)
        trials = unique
    return trials
