"""How well the data determine identified coefficients: standard errors, correlations and
undetermined directions from the curvature of the multi-step loss.

The residuals are those of the multi-step velocity loss the coefficients were identified
with: every window is integrated (`rollout`, the rules of `sysid.dynamics.integrators`)
from its recorded first state with its recorded inputs,
and r = sqrt(w_v) * (predicted - recorded) for (u, v_m, r) at every later step. With J =
d r / d theta (by forward-mode `torch.func.jacfwd`, theta the coefficients' physical
values), the Gauss-Newton (Fisher) information is F = J^T J and

* ``covariance="gauss_newton"``: Cov = s^2 F^-1, s^2 = r^T r / (n - p), exact for white
  residuals;
* ``covariance="sandwich"`` (default): Cov = F^-1 (sum_w g_w g_w^T) F^-1 * W / (W - p), with
  g_w = J_w^T r_w the score of window w. It stays honest when the residuals of one window
  are correlated (a wrong initial state or a model error propagates along the window), as
  long as windows are independent (do not overlap).

Directions of theta the data do not determine are found in relative coordinates
(theta_i / |theta_i|): an eigenvalue of the scaled information below ``rcond`` times the
largest makes the direction singular (infinite sigma), and a relative sigma above
``threshold`` (default 0.5: the +-2 sigma interval contains zero) makes it weak.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np
import torch
from torch import nn
from torch.func import functional_call, jacfwd

from sysid.config.choices import Method
from sysid.dynamics import integrators
from sysid.dynamics.equations import derivative
from sysid.mmg.coefficients import raw_value
from sysid.channel_names import VELOCITY_INDEX

COVARIANCES = ("sandwich", "gauss_newton")


@dataclass(frozen=True)
class CoefficientUncertainty:
    """Estimates with their uncertainty (plain floats and lists, JSON-ready via `as_dict`).

    names : identified coefficient names, order of every array.
    estimate : (p,) values at which the curvature was taken.
    std_error : (p,) one-sigma standard errors (inf in a singular direction).
    covariance, correlation : (p, p).
    undetermined : (p,) True where the +-`threshold`-relative sigma is exceeded or the
        coefficient takes part in a singular direction.
    weak_directions : [{"relative_sigma": s, "combination": {name: weight}}] unit vectors in
        relative coordinates whose sigma exceeds `threshold` (largest first).
    residual_rms : root mean square of the weighted residuals.
    n_residuals, n_windows : residual count and window count.
    method : "sandwich" or "gauss_newton".
    """

    names: tuple[str, ...]
    estimate: np.ndarray
    std_error: np.ndarray
    covariance: np.ndarray
    correlation: np.ndarray
    undetermined: np.ndarray
    weak_directions: list[dict] = field(default_factory=list)
    residual_rms: float = math.nan
    n_residuals: int = 0
    n_windows: int = 0
    method: str = "sandwich"

    def interval(self, k: float = 2.0) -> np.ndarray:
        """(p, 2) estimate -+ k sigma."""
        return np.stack([self.estimate - k * self.std_error, self.estimate + k * self.std_error], -1)

    def as_dict(self) -> dict:
        """Plain-JSON form (inf written as None) for a run summary."""
        def clean(a):
            return [None if not math.isfinite(x) else float(x) for x in np.ravel(a)]
        p = len(self.names)
        return {
            "names": list(self.names),
            "estimate": clean(self.estimate),
            "std_error": clean(self.std_error),
            "correlation": [clean(self.correlation[i]) for i in range(p)],
            "undetermined": [bool(x) for x in self.undetermined],
            "weak_directions": self.weak_directions,
            "residual_rms": self.residual_rms,
            "n_residuals": self.n_residuals,
            "n_windows": self.n_windows,
            "method": self.method,
        }

    def table(self, prior: dict[str, float] | None = None) -> str:
        """Markdown table: name, estimate +- 2 sigma, (prior), flag."""
        head = "| coefficient | estimate | ± 2σ |" + (" prior |" if prior else "") + " determined |"
        rows = [head, "|---|---|---|" + ("---|" if prior else "") + "---|"]
        for i, name in enumerate(self.names):
            prior_cell = f" {prior[name]:.5g} |" if prior else ""
            flag = "no" if self.undetermined[i] else "yes"
            rows.append(f"| {name} | {self.estimate[i]:.5g} | {2 * self.std_error[i]:.3g} |{prior_cell} {flag} |")
        return "\n".join(rows)


def rollout(model: nn.Module, x0: torch.Tensor, inputs: torch.Tensor, dt: float,
            method: Method = Method.EULER) -> torch.Tensor:
    """Fixed-step prediction (T, ..., 6) from x0 (..., 6) with inputs (T, ..., 4) held over
    each step: the step loop of `sysid.dynamics.integrators.rollout` (no torchdiffeq), so
    forward-mode transforms (`torch.func.jacfwd`) pass through it; the same numbers as
    `sysid.dynamics.equations.integrate` with Euler or classical RK4."""
    return integrators.rollout(lambda s, u: derivative(model, s, u), x0, inputs, dt, method)


class _Rollout(nn.Module):
    """Wraps a force model so `functional_call` can swap its coefficients for a whole rollout."""

    def __init__(self, model: nn.Module, method: Method):
        super().__init__()
        self.model = model
        self.method = method

    def forward(self, start, inputs, dt):
        return rollout(self.model, start, inputs, dt, self.method)


def _coefficient_prefix(model: nn.Module) -> str:
    for name, module in model.named_modules():
        if module is model.coefficients:
            return f"{name}." if name else ""
    raise ValueError("the model's coefficients are not among its submodules")


def velocity_weights(states: torch.Tensor) -> torch.Tensor:
    """(3,) w_v = 1 / variance of the recorded (u, v_m, r) [s^2/m^2, s^2/m^2, s^2]: the
    multi-step loss's weights (as in training)."""
    vel = states[..., list(VELOCITY_INDEX)].reshape(-1, 3)
    return 1.0 / vel.var(0)


def multistep_residuals(model: nn.Module, windows, names: Sequence[str], weights: torch.Tensor | None = None,
                        method: Method = Method.EULER) -> tuple[Callable[..., torch.Tensor], torch.Tensor]:
    """The residual function theta -> r (T, W, 3) of the multi-step loss, and theta now.

    The function also takes an optional ``start`` (W, 3): the (u, v_m, r) each window starts
    from [m/s, m/s, rad/s] instead of its recorded first sample (the other state components
    stay as recorded); see `sysid.identify.levenberg_marquardt`.

    model : force model carrying ``coefficients`` (MMG, hybrid, ...), left unchanged.
    windows : object with ``states`` (L, W, 6), ``inputs`` (L, W, 4) and ``dt`` [s]
        (e.g. the training `WindowSet`); T = L - 1 predicted steps.
    names : coefficient names (canonical, e.g. ``"Y_v"``) that theta holds.
    weights : (3,) w_v, default `velocity_weights` of the windows.
    method : integrator (Euler as in training, or classical RK4).
    """
    coefficients = model.coefficients
    prefix = _coefficient_prefix(model)
    states, inputs, dt = windows.states, windows.inputs, float(windows.dt)
    weights = velocity_weights(states) if weights is None else torch.as_tensor(weights, dtype=states.dtype)
    root_w = torch.sqrt(weights.to(states.dtype))
    rollout = _Rollout(model, method)
    bounds = getattr(coefficients, "_bounds", {})
    trainable = set(getattr(coefficients, "trainable_names", ()))

    def entry(name: str, value: torch.Tensor) -> tuple[str, torch.Tensor]:
        if name not in trainable:
            return f"model.{prefix}{name}", value
        if name in bounds:  # the raw parameter that maps to `value`
            return f"model.{prefix}raw_{name}", raw_value(value, *bounds[name])
        return f"model.{prefix}raw_{name}", value

    vel = list(VELOCITY_INDEX)

    def residuals(theta: torch.Tensor, start: torch.Tensor | None = None) -> torch.Tensor:
        swapped = dict(entry(n, theta[i]) for i, n in enumerate(names))
        x0 = states[0]
        if start is not None:
            x0 = torch.cat([x0[..., :1], start[..., :1], x0[..., 2:3], start[..., 1:2], x0[..., 4:5],
                            start[..., 2:3]], -1)
        pred = functional_call(rollout, swapped, (x0, inputs, dt))
        return (pred[1:][..., vel] - states[1:][..., vel]) * root_w

    theta = torch.stack([getattr(coefficients, n).detach().to(states.dtype) for n in names])
    return residuals, theta


def coefficient_uncertainty(model: nn.Module, windows, names: Sequence[str], weights: torch.Tensor | None = None,
                            method: Method = Method.EULER, covariance: str = "sandwich", threshold: float = 0.5,
                            rcond: float = 1e-10, penalty: np.ndarray | None = None) -> CoefficientUncertainty:
    """Standard errors, correlations and undetermined directions of `names`.

    Parameters as in `multistep_residuals`; `covariance` is "sandwich" (default, windows as
    independent clusters) or "gauss_newton"; `threshold` is the relative sigma above which a
    coefficient or direction counts as undetermined; `rcond` the relative eigenvalue below
    which the information is singular; `penalty` (p,) the diagonal information of a prior
    the estimate was regularised with (`sysid.identify.levenberg_marquardt.prior_information`).
    Use non-overlapping windows.
    """
    if covariance not in COVARIANCES:
        raise ValueError(f"covariance {covariance!r}: choose one of {', '.join(COVARIANCES)}")
    names = tuple(names)
    residuals, theta = multistep_residuals(model, windows, names, weights, method)
    with torch.no_grad():
        r = residuals(theta)
    J = jacfwd(residuals)(theta).detach()  # (T, W, 3, p)
    return uncertainty_from_jacobian(names, theta, r, J, covariance, threshold, rcond, penalty=penalty)


def uncertainty_from_jacobian(names: Sequence[str], theta: torch.Tensor, r: torch.Tensor, J: torch.Tensor,
                              covariance: str = "sandwich", threshold: float = 0.5,
                              rcond: float = 1e-10, nuisance: int = 0,
                              penalty: np.ndarray | None = None) -> CoefficientUncertainty:
    """The same from residuals r (T, W, k) and their Jacobian J (T, W, k, p); `nuisance` is
    the number of other parameters fitted along (profiled out of J), which the Gauss-Newton
    form's residual variance r^T r / (n - p - nuisance) accounts for.

    `penalty` (p,) [1 / unit^2]: the diagonal information P of a prior's residuals the
    estimate was regularised with. The covariance is then that of the regularised estimate
    over the data's noise, (J^T J + P)^-1 M (J^T J + P)^-1 with M the data's part (the
    scores' spread, or s^2 J^T J): it leaves out the estimate's pull toward the prior."""
    names = tuple(names)
    theta_np = theta.detach().double().numpy()
    p = len(names)
    W = r.shape[1]
    Jw = J.double().permute(1, 0, 2, 3).reshape(W, -1, p).numpy()  # per window
    rw = r.double().permute(1, 0, 2).reshape(W, -1).numpy()
    Jf, rf = Jw.reshape(-1, p), rw.reshape(-1)
    n = rf.size
    scale = np.where(np.abs(theta_np) > 0, np.abs(theta_np), 1.0)  # relative coordinates
    Js = Jf * scale
    data_info = info = Js.T @ Js
    if penalty is not None:
        info = data_info + np.diag(np.asarray(penalty, dtype=float) * scale * scale)
    lam, vec = np.linalg.eigh(info)
    keep = lam > rcond * max(lam.max(), np.finfo(float).tiny)
    info_pinv = (vec[:, keep] / lam[keep]) @ vec[:, keep].T
    if covariance == "gauss_newton":
        spread = info_pinv if penalty is None else info_pinv @ data_info @ info_pinv
        cov_s = spread * float(rf @ rf) / max(n - p - nuisance, 1)
    else:
        scores = np.einsum("wnp,wn->wp", Jw * scale, rw)
        meat = scores.T @ scores * (W / max(W - p, 1))
        cov_s = info_pinv @ meat @ info_pinv
    singular = np.zeros(p, dtype=bool)
    for k in np.flatnonzero(~keep):
        singular |= np.abs(vec[:, k]) > 0.1
    rel_sigma = np.sqrt(np.clip(np.diag(cov_s), 0.0, None))
    rel_sigma[singular] = np.inf
    cov = cov_s * np.outer(scale, scale)
    std = rel_sigma * scale
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov_s / np.outer(rel_sigma, rel_sigma)
    corr[~np.isfinite(corr)] = np.nan
    np.fill_diagonal(corr, 1.0)
    weak = []
    for k in np.flatnonzero(~keep):
        weak.append(_direction(names, vec[:, k], math.inf))
    lam_c, vec_c = np.linalg.eigh(cov_s)
    for k in np.argsort(lam_c)[::-1]:
        sigma = math.sqrt(max(lam_c[k], 0.0))
        if sigma > threshold:
            weak.append(_direction(names, vec_c[:, k], sigma))
    undetermined = singular | (rel_sigma > threshold)
    return CoefficientUncertainty(names, theta_np, std, cov, corr, undetermined, weak,
                                  float(math.sqrt(rf @ rf / max(n, 1))), int(n), int(W), covariance)


def _direction(names, vector, sigma) -> dict:
    vector = vector / np.abs(vector).max() * (1 if vector[np.abs(vector).argmax()] > 0 else -1)
    return {"relative_sigma": None if not math.isfinite(sigma) else float(sigma),
            "combination": {n: round(float(w), 3) for n, w in zip(names, vector) if abs(w) > 0.2}}
