"""Optuna search through Ray Tune: the axes as Tune distributions, and the trainable that
trains every seed of one proposed configuration and reports their mean validation loss."""
from __future__ import annotations

from typing import Any

from sysid.sweep.points import point_name
from sysid.sweep.spec import SweepSpec
from sysid.sweep.trial import TrialData, final_metrics, run_group, run_trial, side_by_side_refusal
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


def config_of(spec: SweepSpec, values: dict[str, Any]) -> dict | None:
    """The Tune config of a configuration ({"section.option": value}), the inverse of
    `values_of`; None when a value lies outside the sweep's axes (another sweep's run)."""
    config = {}
    for axis in spec.axes:
        value = values[axis.key]
        if axis.distribution:
            low, high = axis.bounds
            if not low <= value <= high:
                return None
            config[_param(axis.key)] = value
        elif value in axis.values:
            config[_param(axis.key)] = axis.values.index(value)
        else:
            return None
    return config


def point_of(spec: SweepSpec, config: dict) -> str:
    return point_name(values_of(spec, config))


def optuna_trainable(config: dict, spec: SweepSpec, inbox: Any, data: TrialData) -> None:
    """Every seed of the proposed configuration: side by side (`run_group`) when the sweep
    has no scheduler and the seeds can share, else one after the other (each reporting its
    epochs); the last report is the mean validation loss over the seeds."""
    from ray import tune

    holder = tune.get_context().get_trial_id()
    values = values_of(spec, config)
    trials = [make_trial(spec, values, seed) for seed in spec.seeds]
    if spec.scheduler.kind == "none" and side_by_side_refusal(trials, data) is None:
        rows = run_group(trials, inbox, data, holder, tune.report)
    else:  # a scheduler compares the trial's reports epoch by epoch, seed after seed
        rows = [run_trial(trial, inbox, data, holder, tune.report) for trial in trials]
    tune.report(final_metrics(rows))
