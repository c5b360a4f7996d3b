"""Identification with each window's starting state estimated along with the coefficients.

The multi-step loss of `sysid.uncertainty` integrates every window from its recorded first
sample, as if that sample were exact. It is not: its noise is the same as the samples that
follow, and after the preprocessing's smoothing it is correlated with them, so the fit
leans the coefficients towards explaining the start's error (an errors-in-variables bias).
Here the (u, v_m, r) each window starts from are unknowns (3 per window, "start states")
and the recorded first sample is one more measurement of them, weighted like every other
sample. Stacked per window w, with x_w the start state and y_w(0) its recorded value,

    e_w = [ sqrt(w_v) * (x_w - y_w(0)) ;  sqrt(w_v) * (predicted_w(t) - y_w(t)), t = 1..T ]

and the loss is sum_w |e_w|^2 over the coefficients theta (p) and all x_w (3 W).

Levenberg-Marquardt solves the normal equations by the Schur complement: the start states
of one window touch only that window's residuals, so their block is W separate 3 x 3
matrices and each step costs one p x p solve. The Jacobian comes from forward mode
(`torch.func.jacfwd`) with p + 3 directions: a common shift of all windows' start states
gives each window's own 3 x 3 block since the windows do not interact.

The uncertainty of theta uses the profile Jacobian (the start states projected out,
J~_w = J_theta,w - J_x,w D_w^-1 B_w^T) in `sysid.uncertainty.uncertainty_from_jacobian`:
the sandwich then clusters the profile scores by window, and the Gauss-Newton form counts
the 3 W extra unknowns in its degrees of freedom.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import torch
from torch import nn
from torch.func import jacfwd

from sysid.state import VELOCITY_INDEX
from sysid.uncertainty import (CoefficientUncertainty, multistep_residuals, uncertainty_from_jacobian,
                               velocity_weights)


@dataclass(frozen=True)
class StartStateFit:
    """Result of `identify_with_start_states`.

    coefficients : name -> estimate (physical units).
    start : (W, 3) estimated (u, v_m, r) each window starts from [m/s, m/s, rad/s].
    iterations : Levenberg-Marquardt iterations taken.
    cost : final sum of squared weighted residuals (start measurements included).
    """

    coefficients: dict[str, float]
    start: torch.Tensor
    iterations: int
    cost: float


def start_state_residuals(model: nn.Module, windows, names: Sequence[str], weights: torch.Tensor | None = None,
                          method: str = "euler"):
    """The stacked residual function (theta (p,), start (W, 3)) -> e (T + 1, W, 3), theta now
    and the recorded start (W, 3). e[0] is the start measurement's residual, e[1:] the
    multi-step residuals of `sysid.uncertainty.multistep_residuals` from `start`. Arguments
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


def _jacobians(residuals, theta, start):
    """Residuals e (T+1, W, 3), J_theta (T+1, W, 3, p), J_start (T+1, W, 3, 3) at (theta, start)."""
    def shifted(th, shift):
        return residuals(th, start + shift)
    zero = torch.zeros(3, dtype=start.dtype)
    J_theta, J_start = jacfwd(shifted, argnums=(0, 1))(theta, zero)
    with torch.no_grad():
        e = residuals(theta, start)
    return e, J_theta.detach(), J_start.detach()


def _normal_blocks(e, J_theta, J_start):
    """A (p, p), B (W, p, 3), D (W, 3, 3), g_theta (p,), g_start (W, 3) of the normal equations."""
    A = torch.einsum("twkp,twkq->pq", J_theta, J_theta)
    B = torch.einsum("twkp,twkq->wpq", J_theta, J_start)
    D = torch.einsum("twkp,twkq->wpq", J_start, J_start)
    g_theta = torch.einsum("twkp,twk->p", J_theta, e)
    g_start = torch.einsum("twkq,twk->wq", J_start, e)
    return A, B, D, g_theta, g_start


def _marquardt_step(blocks, lam: float):
    """Step (d_theta (p,), d_start (W, 3)) of damped Gauss-Newton by the Schur complement."""
    A, B, D, g_theta, g_start = blocks
    A_l = A + lam * torch.diag(torch.diag(A))
    D_l = D + lam * torch.diag_embed(torch.diagonal(D, dim1=-2, dim2=-1))
    D_inv = torch.linalg.inv(D_l)
    BD = B @ D_inv                                                   # (W, p, 3)
    S = A_l - torch.einsum("wpq,wrq->pr", BD, B)
    rhs = g_theta - torch.einsum("wpq,wq->p", BD, g_start)
    d_theta = -torch.linalg.solve(S, rhs)
    d_start = -torch.einsum("wqr,wr->wq", D_inv, g_start + torch.einsum("wpq,p->wq", B, d_theta))
    return d_theta, d_start


def identify_with_start_states(model: nn.Module, windows, names: Sequence[str], weights: torch.Tensor | None = None,
                               method: str = "euler", iterations: int = 40, tolerance: float = 1e-7) -> StartStateFit:
    """Levenberg-Marquardt over the coefficients `names` (from the model's current values) and
    every window's start state (from the recorded first samples).

    model : force model carrying ``coefficients`` (left unchanged).
    windows : ``states`` (L, W, 6), ``inputs`` (L, W, 4), ``dt`` [s].
    weights : (3,) w_v for (u, v_m, r), default `velocity_weights` (also the start
        measurement's weights).
    Stops when no coefficient moves by more than `tolerance` relative (and no start state by
    more than `tolerance` times its channel's RMS), or when no damping lowers the cost.
    """
    residuals, theta, recorded = start_state_residuals(model, windows, names, weights, method)
    start = recorded.clone()
    scale = recorded.pow(2).mean(0).sqrt().clamp_min(1e-6)          # (3,) channel RMS
    with torch.no_grad():
        cost = float((residuals(theta, start) ** 2).sum())
    lam, it = 1e-3, 0
    for it in range(1, iterations + 1):
        blocks = _normal_blocks(*_jacobians(residuals, theta, start))
        while True:
            d_theta, d_start = _marquardt_step(blocks, lam)
            with torch.no_grad():
                trial = float((residuals(theta + d_theta, start + d_start) ** 2).sum())
            if math.isfinite(trial) and trial <= cost:
                theta, start, cost, lam = theta + d_theta, start + d_start, trial, max(lam / 5, 1e-9)
                break
            lam *= 4
            if lam > 1e8:
                return StartStateFit(dict(zip(names, theta.tolist())), start, it, cost)
        small_theta = torch.all(d_theta.abs() <= tolerance * theta.abs().clamp_min(1e-3))
        small_start = torch.all(d_start.abs() <= tolerance * scale)
        if small_theta and small_start:
            break
    return StartStateFit(dict(zip(names, theta.tolist())), start, it, cost)


def start_state_uncertainty(model: nn.Module, windows, names: Sequence[str], start: torch.Tensor,
                            weights: torch.Tensor | None = None, method: str = "euler",
                            covariance: str = "sandwich", threshold: float = 0.5,
                            rcond: float = 1e-10) -> CoefficientUncertainty:
    """Sigma of the coefficients `names` (the model's current values, e.g. set from a
    `StartStateFit`) with the start states `start` (W, 3) fitted along: the profile Jacobian
    in `uncertainty_from_jacobian` (other arguments as in `coefficient_uncertainty`)."""
    residuals, theta, _ = start_state_residuals(model, windows, names, weights, method)
    e, J_theta, J_start = _jacobians(residuals, theta, start)
    _, B, D, _, _ = _normal_blocks(e, J_theta, J_start)
    projected = torch.linalg.solve(D, B.transpose(1, 2))             # D^-1 B^T: (W, 3, p)
    profile = J_theta - torch.einsum("twkq,wqp->twkp", J_start, projected)
    return uncertainty_from_jacobian(names, theta, e, profile, covariance, threshold, rcond,
                                     nuisance=3 * start.shape[0])
