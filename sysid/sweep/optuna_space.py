"""Optuna search through Ray Tune: the axes as Tune distributions, and the trainable that
trains every seed of one proposed configuration and reports their mean validation loss."""
from __future__ import annotations

import math

from sysid.sweep.points import point_name
from sysid.sweep.spec import SweepSpec
from sysid.sweep.trial import TrialContext, run_trial
from sysid.sweep.plan import make_trial


def _param(key: str) -> str:
    return key.replace(".", "__")


def optuna_space(spec: SweepSpec) -> dict:
    """{parameter: Tune distribution}; lists are choices (tuples by index: Optuna stores
    only plain values)."""
    from ray import tune

    space = {}
    for axis in spec.axes:
        low, high = axis.bounds
        if axis.distribution == "uniform":
            space[_param(axis.key)] = tune.uniform(low, high)
        elif axis.distribution == "loguniform":
            space[_param(axis.key)] = tune.loguniform(low, high)
        elif axis.distribution == "randint":
            space[_param(axis.key)] = tune.randint(int(low), int(high))
        else:
            space[_param(axis.key)] = tune.choice(list(range(len(axis.values))))
    return space


def values_of(spec: SweepSpec, config: dict) -> dict:
    """The configuration's {"section.option": value} from a Tune config."""
    values = {}
    for axis in spec.axes:
        raw = config[_param(axis.key)]
        values[axis.key] = axis.values[int(raw)] if not axis.distribution else (
            int(raw) if axis.distribution == "randint" else float(raw))
    return values


def point_of(spec: SweepSpec, config: dict) -> str:
    return point_name(values_of(spec, config))


def optuna_trainable(config: dict, spec: SweepSpec, context: TrialContext) -> None:
    """Every seed of the proposed configuration, one after the other; reports the mean."""
    from ray import tune

    values = values_of(spec, config)
    losses = [run_trial(make_trial(spec, values, seed), context)["val_loss_multistep"] for seed in spec.seeds]
    finite = [v for v in losses if math.isfinite(v)]
    tune.report({"val_loss_multistep": sum(finite) / len(finite) if len(finite) == len(losses) else math.inf})
