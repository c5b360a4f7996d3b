"""The identification interface: a strategy fits the MMG coefficients named in
``[identify] parameters`` of a force model to windows of the training logs.

A strategy is an estimator (scikit-learn's conventions): ``fit(mmg, data)`` sets the
model's coefficients and returns the strategy with what it learned in attributes ending in
``_``; it writes nothing and logs nothing. The training loop's checkpointing and logging
parts, when a strategy runs the loop (gradient), are the caller's
(`sysid.identify.loop.TrainingLoop`). Strategies: `gradient.GradientIdentification` (Adam on
the multi-step loss, Euler rollouts through torchdiffeq's ``odeint``) and
`least_squares.LevenbergMarquardtIdentification`; a fused or compiled gradient step is a
`sysid.identify.loop.GradientStep` given to the loop the gradient strategy runs.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Callable

import torch

from sysid.config.experiment import Experiment
from sysid.dynamics.rollouts import WindowSet
from sysid.identify.loop import StageResult
from sysid.identify.uncertainty import CoefficientUncertainty
from sysid.records.summary import IdentificationSummary


@dataclass(frozen=True)
class IdentificationData:
    """What a strategy identifies on: the training and validation windows (T+1 samples,
    as training), w_v (3,) [s^2/m^2, s^2/m^2, s^2/rad^2] (1 / variance of u, v_m, r), and
    the disjoint windows of the training part (slid by T+1, no shared sample) in a dtype."""

    train: WindowSet
    val: WindowSet
    w_v: torch.Tensor
    disjoint: Callable[[torch.dtype], WindowSet]


class Identification(ABC):
    """A way to identify MMG coefficients.

    Learned (after `fit`): ``stage_`` (`StageResult`: history rows, best epoch, why it
    stopped), ``uncertainty_`` (`CoefficientUncertainty` of the estimate) and
    ``estimator_`` (what identified them, for the run's summary).
    """

    def __init__(self, experiment: Experiment):
        self.experiment = experiment

    @property
    def names(self) -> list[str]:
        return list(self.experiment.identify.parameters)

    @abstractmethod
    def fit(self, mmg: torch.nn.Module, data: IdentificationData) -> "Identification":
        """Identify the coefficients of `mmg` (set in place); returns self."""

    stage_: StageResult
    uncertainty_: CoefficientUncertainty
    estimator_: IdentificationSummary


def coefficients(mmg: torch.nn.Module, names) -> dict[str, float]:
    """The current values of the coefficients `names` of `mmg`."""
    return {k: float(getattr(mmg.coefficients, k).detach()) for k in names}
