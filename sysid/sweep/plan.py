"""A sweep's trials: every configuration (grid point or random draw) with every seed, each
with a stable run-directory path ``trials/{point}/seed{k}``."""
from __future__ import annotations

from typing import Any

from sysid.sweep.points import point_name, sweep_points, unique_names
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
    """Grid or random sweeps: every point x seed, points in order, seeds inside; a point
    drawn twice by a random search is trained once."""
    points = sweep_points(spec)
    names = unique_names(points)
    first = [values for i, values in enumerate(points) if names[i] not in names[:i]]
    return [make_trial(spec, values, seed) for values in first for seed in spec.seeds]
