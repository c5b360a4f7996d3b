"""Rudder and engine orders of standard maneuvers as a function of the state: closed loop.

Every maneuver of a batch is one row of a parameter tensor (`order_parameters`, columns
`COLUMNS`); the controller state of a row is (rudder angle [rad], side of the rudder order
+1/-1). At each step the `ManeuverOrders` module reads the heading, reverses a zig-zag's
order when the heading deviation from the approach course has reached the check angle on
the side the rudder turns to, moves the rudder toward the order at most at the steering
rate, and gives the inputs held over the step: the rudder's exact mean over the step (the
rate-limited angle moves linearly, so a held input matches the moving rudder to second
order in dt), the propeller revolutions (ramped to the crash stop's astern revolutions) and
the wind. Turning circles never reverse (check angle infinite); a crash stop orders the
rudder amidships.

Pure tensor operations, batched over rows, no Python branch on values: the same module
runs eagerly and inside a compiled loop.
"""
from __future__ import annotations

import math
from typing import Sequence

import torch
from torch import nn

from sysid.maneuvers.base import Conditions, Maneuver

COLUMNS = ("rudder", "check", "rate", "rps_ahead", "rps_order", "reversal", "wind_speed", "wind_direction", "psi0")
(RUDDER, CHECK, RATE, RPS_AHEAD, RPS_ORDER, REVERSAL, WIND_SPEED, WIND_DIRECTION, PSI0) = range(len(COLUMNS))


def order_parameters(maneuvers: Sequence[Maneuver], conditions: Conditions,
                     dtype: torch.dtype = torch.float64) -> torch.Tensor:
    """(B, len(COLUMNS)) per maneuver: rudder order magnitude [rad], check angle [rad] (inf:
    never reverse), steering rate [rad/s], approach and ordered revolutions [rps], time to
    reach the ordered revolutions [s], wind speed [m/s] and direction [rad], heading of the
    approach course [rad]."""
    rows = []
    rate = conditions.rudder_rate * math.pi / 180.0
    for m in maneuvers:
        rudder, check, order, reversal = 0.0, math.inf, conditions.rps, 0.0
        if m.kind in ("turning", "zigzag"):
            rudder = math.radians(m.rudder_deg)  # type: ignore[union-attr]
        if m.kind == "zigzag":
            check = math.radians(m.check_deg)  # type: ignore[union-attr]
        if m.kind == "crash_stop":
            order = -conditions.rps if m.astern_rps is None else m.astern_rps  # type: ignore[union-attr]
            reversal = m.reversal_s  # type: ignore[union-attr]
        rows.append([rudder, check, rate, conditions.rps, order, reversal, conditions.wind_speed,
                     conditions.wind_direction, 0.0])
    return torch.tensor(rows, dtype=dtype)


def initial_orders(maneuvers: Sequence[Maneuver], dtype: torch.dtype = torch.float64) -> torch.Tensor:
    """(B, 2) controller state at the execute: rudder amidships, order to the maneuver's side."""
    return torch.tensor([[0.0, m.side.sign if m.kind != "crash_stop" else 1.0] for m in maneuvers], dtype=dtype)  # type: ignore[union-attr]


def rate_limited(angle: torch.Tensor, order: torch.Tensor, rate_dt: torch.Tensor,
                 safe: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
    """(mean over the step, angle at its end) of a rudder at `angle` moving toward `order`
    at most `rate_dt` [rad] per step (all (B,), rad); `safe`: rate_dt where positive, else 1
    (computed here when not given)."""
    gap = order - angle
    size = gap.abs()
    direction = torch.sign(gap)
    full = size >= rate_dt  # still moving at the end of the step
    if safe is None:
        safe = torch.where(rate_dt > 0, rate_dt, torch.ones_like(rate_dt))
    mean = torch.where(full, angle + 0.5 * direction * rate_dt, order - 0.5 * direction * size * size / safe)
    end = torch.where(full, angle + direction * rate_dt, order)
    return mean, end


class ManeuverOrders(nn.Module):
    """Inputs held over one step and the next controller state, from the state at its start.

    ``forward(state (B, 6), orders (B, 2), parameters (B, P), t (), dt ())`` with t the time
    since the execute [s] at the step's start and dt the step [s]; returns (inputs (B, 4),
    orders after the step (B, 2)).
    """

    def forward(self, state: torch.Tensor, orders: torch.Tensor, parameters: torch.Tensor,
                t: torch.Tensor, dt: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        p = parameters
        angle, side = orders[:, 0], orders[:, 1]
        deviation = state[:, 4] - p[:, PSI0]
        reverse = side * deviation >= p[:, CHECK]
        side = torch.where(reverse, -side, side)
        mean, end = rate_limited(angle, side * p[:, RUDDER], p[:, RATE] * dt)
        reversal = p[:, REVERSAL]
        ramping = reversal > 0
        share = ((t + 0.5 * dt) / torch.where(ramping, reversal, torch.ones_like(reversal))).clamp(0.0, 1.0)
        ramp = torch.where(ramping, share, torch.ones_like(reversal))  # at mid-step: the mean over a linear ramp
        rps = p[:, RPS_AHEAD] + ramp * (p[:, RPS_ORDER] - p[:, RPS_AHEAD])
        inputs = torch.stack((rps, mean, p[:, WIND_SPEED], p[:, WIND_DIRECTION]), -1)
        return inputs, torch.stack((end, side), -1)

    @staticmethod
    def held(parameters: torch.Tensor, dt: torch.Tensor):
        """`forward` for fixed parameters (B, P) and step dt (), as a function (state (B, 6),
        orders (B, 2), t ()) -> (inputs (B, 4), orders after the step (B, 2)) with what does
        not change from step to step taken once (the eager loop's): the same operations
        on the same numbers, so the same bits."""
        p = parameters
        psi0, check, rudder = p[:, PSI0], p[:, CHECK], p[:, RUDDER]
        rate_dt = p[:, RATE] * dt
        safe = torch.where(rate_dt > 0, rate_dt, torch.ones_like(rate_dt))
        reversal = p[:, REVERSAL]
        ramping = reversal > 0
        ones = torch.ones_like(reversal)
        divisor = torch.where(ramping, reversal, ones)
        ahead = p[:, RPS_AHEAD]
        span = p[:, RPS_ORDER] - ahead
        wind = (p[:, WIND_SPEED], p[:, WIND_DIRECTION])
        steady = None if bool(ramping.any()) else ahead + ones * span  # no ramp: the ramp is 1 throughout

        def orders_over(state: torch.Tensor, orders: torch.Tensor, t: torch.Tensor):
            angle, side = orders[:, 0], orders[:, 1]
            deviation = state[:, 4] - psi0
            side = torch.where(side * deviation >= check, -side, side)
            mean, end = rate_limited(angle, side * rudder, rate_dt, safe)
            if steady is None:
                share = ((t + 0.5 * dt) / divisor).clamp(0.0, 1.0)
                rps = ahead + torch.where(ramping, share, ones) * span
            else:
                rps = steady
            return torch.stack((rps, mean, *wind), -1), torch.stack((end, side), -1)
        return orders_over
