"""The propeller revolutions that hold the approach speed in straight running, from the model.

Straight running at U0: u = U0, v_m = r = 0, rudder amidships; the revolutions n are those
at which the model's surge acceleration du/dt vanishes there. du/dt is evaluated on a grid
of n in one batched call, the first sign change from slowing down to speeding up is
bracketed, and bisection narrows it to two neighbouring floats (about 46 evaluations of one
row; no root-finding library to import). Any force model works (MMG, NN-only, hybrid,
ensemble): only its right-hand side is used.
"""
from __future__ import annotations

import math

import numpy as np
import torch
from torch import nn

from sysid.dynamics.equations import derivative
from sysid.maneuvers.base import ManeuverError

MAX_RPS = 200.0  # [rps] upper end of the search: beyond any ship's or model's propeller
GRID = 2001


def straight_rows(model: nn.Module, speed: float, rps: np.ndarray, wind_speed: float = 0.0,
                  wind_direction: float = 0.0) -> tuple[torch.Tensor, torch.Tensor]:
    """(states (N, 6), inputs (N, 4)) of straight running at `speed` [m/s] for revolutions
    `rps` (N,) [rps], rudder amidships, true wind `wind_speed` [m/s] from `wind_direction`
    [rad], in the model's dtype."""
    dtype = next((t.dtype for t in model.buffers() if t.is_floating_point()), torch.float64)
    n = torch.as_tensor(np.atleast_1d(rps), dtype=dtype)
    state = torch.zeros(len(n), 6, dtype=dtype)
    state[:, 1] = speed
    wind = (torch.full_like(n, wind_speed), torch.full_like(n, wind_direction))
    return state, torch.stack((n, torch.zeros_like(n), *wind), -1)


def _gate_off_note(model: nn.Module, speed: float, rps: float, wind_speed: float, wind_direction: float) -> str:
    """Words for a straight run at `rps` that lies outside the model's training data (its kNN
    gate off there: the FNN switched off); "" where the gate is on or the model has none."""
    decide = getattr(model, "gate_decision", None)
    if decide is None:
        return ""
    with torch.no_grad():
        on = decide(*straight_rows(model, speed, np.array([rps]), wind_speed, wind_direction))
    if on is None or bool(on.all()):
        return ""
    bare = "NN-only has no force there" if str(getattr(model, "kind", "")) == "nn" else "the MMG alone acts there"
    return (f"; at {rps:g} rps the kNN gate is off: straight running there lies outside the training data "
            f"(the FNN is switched off, {bare})")


def surge_acceleration(model: nn.Module, speed: float, rps: np.ndarray, wind_speed: float = 0.0,
                       wind_direction: float = 0.0) -> np.ndarray:
    """du/dt [m/s^2] (N,) in straight running at `speed` [m/s] for revolutions `rps` (N,)
    [rps], rudder amidships, true wind `wind_speed` [m/s] from `wind_direction` [rad]."""
    state, inputs = straight_rows(model, speed, rps, wind_speed, wind_direction)
    with torch.no_grad():
        return derivative(model, state, inputs)[:, 1].double().numpy()


def straight_running_rps(model: nn.Module, speed: float, wind_speed: float = 0.0, wind_direction: float = 0.0,
                         max_rps: float = MAX_RPS) -> float:
    """Propeller revolutions [rps] at which `model` holds `speed` [m/s] in straight running
    (du/dt = 0 at u = speed, v_m = r = 0, rudder amidships): the lowest such n in
    [0, max_rps]. `ManeuverError` when the model gives none."""
    grid = np.linspace(0.0, max_rps, GRID)
    accel = surge_acceleration(model, speed, grid, wind_speed, wind_direction)
    if not np.isfinite(accel).all():
        raise ManeuverError(f"the model's surge acceleration at {speed:g} m/s is not finite for some revolutions "
                            f"in 0..{max_rps:g} rps; pass the revolutions (--rps)")
    if accel[0] >= 0.0:
        raise ManeuverError(f"the model does not slow down at {speed:g} m/s with the propeller stopped "
                            f"(du/dt = {accel[0]:.3g} m/s^2{_gate_off_note(model, speed, 0.0, wind_speed, wind_direction)})"
                            ": no straight-running revolutions; pass --rps")
    rising = np.nonzero((accel[:-1] < 0.0) & (accel[1:] >= 0.0))[0]
    if not len(rising):
        raise ManeuverError(f"no propeller revolutions in 0..{max_rps:g} rps hold {speed:g} m/s in the model "
                            f"(du/dt stays below {accel.max():.3g} m/s^2); pass --rps or a lower --speed")
    i = int(rising[0])
    if accel[i + 1] == 0.0:
        return float(grid[i + 1])
    root = sign_change(lambda n: float(surge_acceleration(model, speed, np.array([n]), wind_speed, wind_direction)[0]),
                       float(grid[i]), float(grid[i + 1]), float(accel[i]), float(accel[i + 1]))
    if not math.isfinite(root):
        raise ManeuverError(f"straight-running revolutions at {speed:g} m/s: the search did not converge; pass --rps")
    return root


def sign_change(f, low: float, high: float, f_low: float, f_high: float) -> float:
    """Where f changes sign from f(low) = f_low < 0 to f(high) = f_high >= 0: bisection until
    no float lies between the ends, then the end where |f| is smaller; NaN where f is not
    finite on the way."""
    while True:
        middle = 0.5 * (low + high)
        if not low < middle < high:
            break
        value = f(middle)
        if not math.isfinite(value):
            return math.nan
        if value < 0.0:
            low, f_low = middle, value
        else:
            high, f_high = middle, value
    return low if abs(f_low) < abs(f_high) else high
