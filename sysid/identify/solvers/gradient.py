"""Identification by gradient: Adam on the multi-step loss (Euler rollouts of T steps
through torchdiffeq's ``odeint`` from each window's recorded start), early stopping on the
validation loss, run by the training loop; the sigma from the multi-step residuals on
disjoint windows (`sysid.identify.uncertainty`, the sandwich)."""
from __future__ import annotations

import torch

from sysid.config.choices import Method, Solver, Stage, StartStates
from sysid.identify.loop import TrainingLoop
from sysid.identify.solvers.base import Identification, IdentificationData
from sysid.identify.uncertainty import CoefficientUncertainty, coefficient_uncertainty
from sysid.records.summary import IdentificationSummary


def gradient_uncertainty(model, disjoint, names, w_v) -> CoefficientUncertainty:
    """Standard errors and correlations of the identified coefficients of `model` from the
    multi-step residuals on the `disjoint` windows, each from its recorded start."""
    return coefficient_uncertainty(model, disjoint, list(names), w_v)


def gradient_estimator(epochs: int, joint: bool) -> IdentificationSummary:
    """What identified the coefficients with ``solver = "gradient"`` (for the summary)."""
    return IdentificationSummary(solver=Solver.GRADIENT, start_states=StartStates.RECORDED, epochs=epochs,
                                 stage="joint with the FNN" if joint else Stage.BEFORE.value,
                                 integrator=Method.EULER.value, covariance="sandwich")


class GradientIdentification(Identification):
    """``[identify] solver = "gradient"``, stage "before" (or MMG-only): the coefficients
    alone trained by `loop` (``[identify] epochs`` and ``learning_rate``, stage "identify")."""

    def __init__(self, experiment, loop: TrainingLoop):
        super().__init__(experiment)
        self.loop = loop

    def fit(self, mmg: torch.nn.Module, data: IdentificationData) -> "GradientIdentification":
        ident = self.experiment.identify
        self.stage_ = self.loop.run(mmg, list(mmg.parameters()), data.train, data.val, data.w_v, None,
                                    ident.epochs, ident.learning_rate, "identify")
        dtype = data.train.states.dtype
        self.uncertainty_ = gradient_uncertainty(mmg, data.disjoint(dtype), self.names, data.w_v)
        self.estimator_ = gradient_estimator(len(self.stage_.history), joint=False)
        return self
