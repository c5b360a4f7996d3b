"""Identification by Levenberg-Marquardt: least squares on the multi-step residuals of the
disjoint windows of the training part in float64, integrated by `[identify] integrator`
(Euler, as training, by default), start states and prior as configured (`sysid.identify.levenberg_marquardt`), the sigma of that estimator, and
the same fit with the other start-state treatment beside it (`start_state_check`)."""
from __future__ import annotations

import time

import torch

from sysid.config.choices import Method, Solver
from sysid.hybrid.force_models import build_mmg
from sysid.identify.levenberg_marquardt import fit_uncertainty, identify_levenberg_marquardt, start_state_check
from sysid.identify.losses import multistep_loss
from sysid.identify.loop import StageResult
from sysid.identify.solvers.base import Identification, IdentificationData, coefficients
from sysid.records.summary import IdentificationSummary


class LevenbergMarquardtIdentification(Identification):
    """``[identify] solver = "levenberg_marquardt"`` (``start_states``, ``prior_weight``,
    ``iterations``).

    Learned besides the interface's: ``fit_`` (`LevenbergMarquardtFit`), ``check_``
    (`StartStateCheck`), ``windows_`` (disjoint windows fitted), ``train_loss_`` and
    ``val_loss_`` (the identified MMG's multi-step loss L_v on the training and validation
    windows) and ``check_val_loss_`` (the other treatment's on the validation windows).
    ``stage_`` holds one history row: those losses at ``epoch`` = the iterations taken.
    """

    @property
    def start_states(self):
        return self.experiment.identify.start_states

    def _fit_float64(self, data: IdentificationData, device) -> None:
        """The fit, its sigma and its start-state check on the disjoint windows in float64
        (identification's precision), each on a fresh MMG of the configured coefficients."""
        ident, names = self.experiment.identify, self.names
        windows = data.disjoint(torch.float64)
        model = build_mmg(self.experiment, torch.float64).to(device)
        prior = coefficients(model, names)
        weights = data.w_v.to(torch.float64)
        fit = identify_levenberg_marquardt(model, windows, names, weights, ident.integrator, ident.start_states, prior,
                                           ident.prior_weight, ident.iterations)
        model.coefficients.assign(fit.coefficients)
        self.uncertainty_ = fit_uncertainty(model, windows, names, fit, weights, ident.integrator, prior=prior,
                                            prior_weight=ident.prior_weight)
        self.check_ = start_state_check(build_mmg(self.experiment, torch.float64).to(device), windows, names, fit,
                                        self.uncertainty_.std_error, weights, ident.integrator, prior,
                                        ident.prior_weight, ident.iterations)
        self.fit_, self.windows_ = fit, len(windows)

    def fit(self, mmg: torch.nn.Module, data: IdentificationData) -> "LevenbergMarquardtIdentification":
        ident = self.experiment.identify
        started = time.perf_counter()
        self._fit_float64(data, data.train.states.device)
        fit, check = self.fit_, self.check_
        with torch.no_grad():
            mmg.coefficients.assign(check.coefficients)
            self.check_val_loss_ = float(multistep_loss(mmg, data.val, data.w_v)[0])
            mmg.coefficients.assign(fit.coefficients)
            self.train_loss_, self.val_loss_ = (float(multistep_loss(mmg, w, data.w_v)[0])
                                                for w in (data.train, data.val))
        row = {"stage": "identify", "epoch": fit.iterations, "train_loss": self.train_loss_,
               "train_velocity": self.train_loss_, "train_penalty": 0.0, "early_stopping_loss": self.val_loss_,
               "seconds": time.perf_counter() - started}
        self.stage_ = StageResult([row], fit.iterations, self.val_loss_, fit.stopped)
        self.estimator_ = IdentificationSummary(
            solver=Solver.LEVENBERG_MARQUARDT, start_states=ident.start_states, prior_weight=ident.prior_weight,
            iterations=fit.iterations, windows=self.windows_, integrator=Method(ident.integrator).value,
            covariance=self.uncertainty_.method, start_state_check=check.summary(self.check_val_loss_))
        return self
