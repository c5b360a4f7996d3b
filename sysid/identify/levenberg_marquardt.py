"""Identification of coefficients by Levenberg-Marquardt on the multi-step residuals, each
window's start state recorded or estimated, and the sigma of that estimate.

The residuals are those of `sysid.identify.uncertainty.multistep_residuals`: every window is
integrated from its start with its recorded inputs, e = sqrt(w_v) * (predicted - recorded)
for (u, v_m, r) at every later step. Two ways of starting a window:

* ``start_states="recorded"``: from its recorded first sample, taken as exact (the
  multi-step loss of training). Unknowns: the p coefficients theta.
* ``start_states="estimated"``: the (u, v_m, r) each window starts from are unknowns too
  (3 per window, "start states") and the recorded first sample is one more measurement of
  them, weighted like every other sample. Per window w, with x_w the start state and
  y_w(0) its recorded value,

      e_w = [ sqrt(w_v) * (x_w - y_w(0)) ;  sqrt(w_v) * (predicted_w(t) - y_w(t)), t = 1..T ]

  The recorded first sample is not exact: its noise is that of every other sample and,
  after the preprocessing's smoothing, correlated with them, so integrating from it leans
  the coefficients towards explaining the start's error (an errors-in-variables bias).
  This is the estimator whose +-2 sigma covered the truth in about 95 % of runs through
  raw logs (benchmarks/identification_results.md).

Optionally a prior: ``prior_weight`` = lambda >= 0 appends, per coefficient, the residual
sqrt(lambda) * (theta_i - prior_i) / |prior_i| (|prior_i| taken as 1 where the prior is 0),
so lambda = 1 costs a 100 % departure from the prior as much as one weighted residual of 1
(with the default weights 1 / variance of each recorded channel: one sample off by that
channel's standard deviation). Its information lambda / prior_i^2 enters the sigma too
(`prior_information`); that sigma is the regularised estimate's spread over the noise and
leaves out its pull toward the prior.

Levenberg-Marquardt minimises sum |e|^2 (+ the prior's) with Marquardt's diagonal damping.
With estimated start states the normal equations are solved by the Schur complement: the
start states of one window touch only that window's residuals, so their block is W separate
3 x 3 matrices and each step costs one p x p solve. Jacobians by forward mode
(`torch.func.jacfwd`): p directions, plus 3 for the start states (a common shift of all
windows' start states gives each window's own 3 x 3 block since the windows do not
interact).

The sigma of theta (`fit_uncertainty`): with recorded starts `coefficient_uncertainty`;
with estimated ones the profile Jacobian (start states projected out,
J~_w = J_theta,w - J_x,w D_w^-1 B_w^T) in `sysid.identify.uncertainty.uncertainty_from_jacobian`:
the sandwich then clusters the profile scores by window, and the Gauss-Newton form counts
the 3 W extra unknowns in its degrees of freedom.

A model-error check (`start_state_check`): the same fit with the other start-state
treatment. Where the model structure is right and the starts are accurate both estimates
land within the sigma of each other. A larger gap says the sigma, which measures the noise
only, is not the whole uncertainty: either the recorded starts are noisy (the recorded fit
carries the errors-in-variables bias) or the model structure is wrong (free start states
take up part of the model error, the recorded fit puts it into the coefficients).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np
import torch
from torch import nn
from torch.func import jacfwd

from sysid.config.choices import Method, StartStates
from sysid.records.summary import start_state_verdict
from sysid.channel_names import VELOCITY_INDEX
from sysid.identify.uncertainty import (CoefficientUncertainty, coefficient_uncertainty, multistep_residuals,
                               uncertainty_from_jacobian, velocity_weights)

CHECK_LIMIT = 2.0  # |difference| / sigma beyond which the two start-state treatments disagree


@dataclass(frozen=True)
class LevenbergMarquardtFit:
    """Result of `identify_levenberg_marquardt`.

    coefficients : name -> estimate (physical units).
    start : (W, 3) (u, v_m, r) each window starts from [m/s, m/s, rad/s]: estimated, or the
        recorded first samples.
    start_states : estimated or recorded.
    iterations : Levenberg-Marquardt iterations taken.
    cost : final sum of squared weighted residuals (start measurements and prior included).
    stopped : "converged" (no coefficient, nor start state, moved by more than the tolerance),
        "stalled" (no damping lowered the cost: at the minimum to rounding, or stuck) or
        "iteration limit".
    """

    coefficients: dict[str, float]
    start: torch.Tensor
    start_states: StartStates
    iterations: int
    cost: float
    stopped: str


def start_state_residuals(model: nn.Module, windows, names: Sequence[str], weights: torch.Tensor | None = None,
                          method: Method = Method.EULER):
    """The stacked residual function (theta (p,), start (W, 3)) -> e (T + 1, W, 3), theta now
    and the recorded start (W, 3). e[0] is the start measurement's residual, e[1:] the
    multi-step residuals of `sysid.identify.uncertainty.multistep_residuals` from `start`. Arguments
    as there (windows: ``states`` (L, W, 6), ``inputs`` (L, W, 4), ``dt`` [s])."""
    states = windows.states
    weights = velocity_weights(states) if weights is None else torch.as_tensor(weights, dtype=states.dtype)
    root_w = torch.sqrt(weights.to(states.dtype))
    multistep, theta = multistep_residuals(model, windows, names, weights, method)
    recorded = states[0][..., list(VELOCITY_INDEX)]

    def residuals(theta: torch.Tensor, start: torch.Tensor) -> torch.Tensor:
        first = (start - recorded) * root_w
        return torch.cat([first[None], multistep(theta, start)])

    return residuals, theta, recorded


def _residual_function(model, windows, names, weights, method: Method, start_states: StartStates):
    """(theta, start) -> e, theta now, recorded start (W, 3); with recorded starts e is the
    plain multi-step residual (T, W, 3) and `start` is not used."""
    if start_states is StartStates.ESTIMATED:
        return start_state_residuals(model, windows, names, weights, method)
    multistep, theta = multistep_residuals(model, windows, names, weights, method)
    return (lambda th, start: multistep(th)), theta, windows.states[0][..., list(VELOCITY_INDEX)]


def _jacobians(residuals, theta, start, estimated: bool):
    """Residuals e (T', W, 3), J_theta (T', W, 3, p), J_start (T', W, 3, 3) (None for
    recorded starts) at (theta, start)."""
    with torch.no_grad():
        e = residuals(theta, start)
    if not estimated:
        return e, jacfwd(lambda th: residuals(th, start))(theta).detach(), None

    def shifted(th, shift):
        return residuals(th, start + shift)
    zero = torch.zeros(3, dtype=start.dtype, device=start.device)
    J_theta, J_start = jacfwd(shifted, argnums=(0, 1))(theta, zero)
    return e, J_theta.detach(), J_start.detach()


def _normal_blocks(e, J_theta, J_start):
    """A (p, p), B (W, p, 3), D (W, 3, 3), g_theta (p,), g_start (W, 3) of the normal
    equations (B, D, g_start None without start states)."""
    if J_start is None:  # (summed as flat products; einsum's order differs in the last bits)
        flat = J_theta.reshape(-1, J_theta.shape[-1])
        return flat.T @ flat, None, None, flat.T @ e.reshape(-1), None
    A = torch.einsum("twkp,twkq->pq", J_theta, J_theta)
    g_theta = torch.einsum("twkp,twk->p", J_theta, e)
    B = torch.einsum("twkp,twkq->wpq", J_theta, J_start)
    D = torch.einsum("twkp,twkq->wpq", J_start, J_start)
    g_start = torch.einsum("twkq,twk->wq", J_start, e)
    return A, B, D, g_theta, g_start


def _marquardt_step(blocks, lam: float):
    """Step (d_theta (p,), d_start (W, 3) or None) of damped Gauss-Newton, the start states
    eliminated by the Schur complement."""
    A, B, D, g_theta, g_start = blocks
    A_l = A + lam * torch.diag(torch.diag(A))
    if B is None:
        return -torch.linalg.solve(A_l, g_theta), None
    D_l = D + lam * torch.diag_embed(torch.diagonal(D, dim1=-2, dim2=-1))
    D_inv = torch.linalg.inv(D_l)
    BD = B @ D_inv                                                   # (W, p, 3)
    S = A_l - torch.einsum("wpq,wrq->pr", BD, B)
    rhs = g_theta - torch.einsum("wpq,wq->p", BD, g_start)
    d_theta = -torch.linalg.solve(S, rhs)
    d_start = -torch.einsum("wqr,wr->wq", D_inv, g_start + torch.einsum("wpq,p->wq", B, d_theta))
    return d_theta, d_start


def prior_scale(prior: torch.Tensor) -> torch.Tensor:
    """|prior| per coefficient, 1 where the prior is 0: the unit of a relative departure."""
    return torch.where(prior != 0, prior.abs(), torch.ones_like(prior))


def prior_information(prior: Mapping[str, float], names: Sequence[str], weight: float) -> np.ndarray:
    """(p,) diagonal information lambda / prior_i^2 [1 / unit^2] that the prior's residuals
    sqrt(lambda) (theta_i - prior_i) / |prior_i| add to the normal matrix."""
    values = torch.tensor([float(prior[n]) for n in names], dtype=torch.float64)
    return (weight / prior_scale(values) ** 2).numpy()


def identify_levenberg_marquardt(model: nn.Module, windows, names: Sequence[str],
                                 weights: torch.Tensor | None = None, method: Method = Method.EULER,
                                 start_states: StartStates | str = StartStates.ESTIMATED, prior: Mapping[str, float] | None = None,
                                 prior_weight: float = 0.0, iterations: int = 40,
                                 tolerance: float = 1e-7) -> LevenbergMarquardtFit:
    """Levenberg-Marquardt over the coefficients `names` (from the model's current values)
    and, with ``start_states="estimated"``, every window's start state (from the recorded
    first samples).

    model : force model carrying ``coefficients`` (left unchanged).
    windows : ``states`` (L, W, 6), ``inputs`` (L, W, 4), ``dt`` [s]; use non-overlapping
        windows (the sigma's sandwich treats them as independent).
    weights : (3,) w_v for (u, v_m, r) [s^2/m^2, s^2/m^2, s^2], default `velocity_weights`
        (also the start measurement's weights).
    method : integrator, Euler (as training) or classical RK4, one step per sample.
    prior, prior_weight : values {name: value} and weight lambda >= 0 of the prior residuals
        (module docstring); the prior defaults to the model's current values.
    Stops when no coefficient moves by more than `tolerance` relative (and no start state by
    more than `tolerance` times its channel's RMS), when no damping lowers the cost, or after
    `iterations`.
    """
    names = tuple(names)
    start_states = StartStates.parse(start_states)  # a Python caller may name it
    estimated = start_states is StartStates.ESTIMATED
    residuals, theta, recorded = _residual_function(model, windows, names, weights, method, start_states)
    start = recorded.clone()
    scale = recorded.pow(2).mean(0).sqrt().clamp_min(1e-6)          # (3,) channel RMS
    prior = dict(zip(names, theta.tolist())) if prior is None else prior
    centre = torch.tensor([float(prior[n]) for n in names], dtype=theta.dtype, device=theta.device)
    info = torch.as_tensor(prior_information(prior, names, prior_weight), dtype=theta.dtype, device=theta.device)

    def total(theta, start) -> float:
        with torch.no_grad():
            return float((residuals(theta, start) ** 2).sum() + (info * (theta - centre) ** 2).sum())

    cost = total(theta, start)
    lam, it, stopped = 1e-3, 0, "iteration limit"
    for it in range(1, iterations + 1):
        A, B, D, g_theta, g_start = _normal_blocks(*_jacobians(residuals, theta, start, estimated))
        if prior_weight:
            A, g_theta = A + torch.diag(info), g_theta + info * (theta - centre)
        blocks = (A, B, D, g_theta, g_start)
        while True:
            d_theta, d_start = _marquardt_step(blocks, lam)
            trial_start = start if d_start is None else start + d_start
            trial = total(theta + d_theta, trial_start)
            if math.isfinite(trial) and trial <= cost:
                theta, start, cost, lam = theta + d_theta, trial_start, trial, max(lam / 5, 1e-9)
                break
            lam *= 4
            if lam > 1e8:
                return LevenbergMarquardtFit(dict(zip(names, theta.tolist())), start, start_states, it, cost,
                                             "stalled")
        small_theta = torch.all(d_theta.abs() <= tolerance * theta.abs().clamp_min(1e-3))
        small_start = d_start is None or torch.all(d_start.abs() <= tolerance * scale)
        if small_theta and small_start:
            stopped = "converged"
            break
    return LevenbergMarquardtFit(dict(zip(names, theta.tolist())), start, start_states, it, cost, stopped)


def start_state_uncertainty(model: nn.Module, windows, names: Sequence[str], start: torch.Tensor,
                            weights: torch.Tensor | None = None, method: Method = Method.EULER,
                            covariance: str = "sandwich", threshold: float = 0.5,
                            rcond: float = 1e-10, penalty: np.ndarray | None = None) -> CoefficientUncertainty:
    """Sigma of the coefficients `names` (the model's current values, e.g. set from a
    `LevenbergMarquardtFit`) with the start states `start` (W, 3) fitted along: the profile
    Jacobian in `uncertainty_from_jacobian` (other arguments as in `coefficient_uncertainty`)."""
    residuals, theta, _ = start_state_residuals(model, windows, names, weights, method)
    e, J_theta, J_start = _jacobians(residuals, theta, start, True)
    _, B, D, _, _ = _normal_blocks(e, J_theta, J_start)
    projected = torch.linalg.solve(D, B.transpose(1, 2))             # D^-1 B^T: (W, 3, p)
    profile = J_theta - torch.einsum("twkq,wqp->twkp", J_start, projected)
    return uncertainty_from_jacobian(names, theta, e, profile, covariance, threshold, rcond,
                                     nuisance=3 * start.shape[0], penalty=penalty)


def fit_uncertainty(model: nn.Module, windows, names: Sequence[str], fit: LevenbergMarquardtFit,
                    weights: torch.Tensor | None = None, method: Method = Method.EULER, covariance: str = "sandwich",
                    prior: Mapping[str, float] | None = None, prior_weight: float = 0.0) -> CoefficientUncertainty:
    """Sigma of a `LevenbergMarquardtFit` as it was identified: `model` carries the fitted
    coefficients; the start states as in the fit (estimated: profiled out; recorded:
    `coefficient_uncertainty`); with `prior_weight` > 0 the prior's information is included
    (`prior`: the values the fit was regularised toward, required then)."""
    if prior_weight and prior is None:
        raise ValueError("prior_weight > 0: give the prior values the fit was regularised toward")
    penalty = prior_information(prior, names, prior_weight) if prior_weight else None
    if fit.start_states is StartStates.ESTIMATED:
        return start_state_uncertainty(model, windows, names, fit.start, weights, method, covariance,
                                       penalty=penalty)
    return coefficient_uncertainty(model, windows, names, weights, method, covariance, penalty=penalty)


@dataclass(frozen=True)
class StartStateCheck:
    """The configured fit beside the same fit with the other start-state treatment.

    start_states : the other treatment (recorded or estimated).
    coefficients : name -> its estimate.
    difference_sigma : name -> (other - configured) / sigma of the configured estimate
        (nan where that sigma is not finite).
    agrees : every |difference_sigma| <= `CHECK_LIMIT`.
    """

    start_states: StartStates
    coefficients: dict[str, float]
    difference_sigma: dict[str, float]

    @property
    def agrees(self) -> bool:
        return all(not abs(d) > CHECK_LIMIT for d in self.difference_sigma.values())

    @property
    def largest(self) -> tuple[str, float]:
        """The coefficient with the largest finite |difference_sigma|, and that value."""
        finite = {k: v for k, v in self.difference_sigma.items() if math.isfinite(v)}
        name = max(finite, key=lambda k: abs(finite[k]), default="")
        return name, finite.get(name, float("nan"))

    def verdict(self) -> str:
        """The check in one clause (`start_state_verdict`)."""
        name, value = self.largest
        return start_state_verdict(self.start_states, name, value if math.isfinite(value) else None, self.agrees)

    def as_dict(self) -> dict:
        name, value = self.largest
        return {"start_states": self.start_states.value, "coefficients": dict(self.coefficients),
                "difference_sigma": {k: (v if math.isfinite(v) else None) for k, v in self.difference_sigma.items()},
                "largest": name, "largest_sigma": value if math.isfinite(value) else None,
                "limit_sigma": CHECK_LIMIT, "agrees": self.agrees}


def start_state_check(model: nn.Module, windows, names: Sequence[str], fit: LevenbergMarquardtFit,
                      sigma: Sequence[float] | np.ndarray, weights: torch.Tensor | None = None, method: Method = Method.EULER,
                      prior: Mapping[str, float] | None = None, prior_weight: float = 0.0,
                      iterations: int = 40) -> StartStateCheck:
    """Fit `names` again with the other start-state treatment than `fit`'s, from the values
    `model` carries (those `fit` started from; left unchanged), with the same windows,
    weights, integrator and prior; compare with `fit` in units of its `sigma` (p,)."""
    other = identify_levenberg_marquardt(model, windows, names, weights, method,
                                         fit.start_states.other, prior, prior_weight, iterations)
    difference = {}
    for name, s in zip(names, sigma):
        s = float("nan") if s is None else float(s)
        gap = other.coefficients[name] - fit.coefficients[name]
        difference[name] = gap / s if math.isfinite(s) and s > 0 else float("nan")
    return StartStateCheck(other.start_states, other.coefficients, difference)
