"""One integration step of a force model as a module, and the step loop around it.

`Step` maps (state (B, 6), inputs (B, 4)) to the state one step of dt later with the
inputs held (Euler, classical RK4 or the 3/8 rule of `sysid.integrators`): the unit that
`sysid.compiled` compiles and `sysid.export` exports. `Derivative` is the bare right-hand
side dx/dt (B, 6). `rollout` runs any step function over a recorded input sequence.

Numbers: `Step` with Euler is bit-identical to torchdiffeq's Euler in
`sysid.dynamics.integrate` (x + dt f(x)); the Runge-Kutta rules agree to round-off.
"""
from __future__ import annotations

from typing import Callable

import torch
from torch import nn

from sysid.dynamics import derivative
from sysid.integrators import STEP_RULES, Method


class Derivative(nn.Module):
    """dx/dt (B, 6) of a force model at states (B, 6) with inputs (B, 4)."""

    def __init__(self, force_model: nn.Module):
        super().__init__()
        self.force_model = force_model

    def forward(self, state: torch.Tensor, inputs: torch.Tensor) -> torch.Tensor:
        return derivative(self.force_model, state, inputs)


class Step(nn.Module):
    """x_{k+1} (B, 6) from x_k (B, 6) and inputs_k (B, 4) held over one step.

    Parameters
    ----------
    force_model : MMG, NN-only or hybrid model (with its kNN gate).
    method : the step rule.
    dt : step length [s].
    """

    def __init__(self, force_model: nn.Module, method: Method | str, dt: float):
        super().__init__()
        self.force_model = force_model
        self.method = Method.parse(method)
        self.dt = float(dt)

    def forward(self, state: torch.Tensor, inputs: torch.Tensor) -> torch.Tensor:
        rule = STEP_RULES[self.method]
        return rule(lambda x: derivative(self.force_model, x, inputs), state, self.dt)


def rollout(rhs: Callable[[torch.Tensor, torch.Tensor], torch.Tensor], x0: torch.Tensor,
            inputs: torch.Tensor, dt: float, method: Method | str) -> torch.Tensor:
    """States (T, ..., 6) from x0 (..., 6) and inputs (T, ..., 4) with the eager step loop.

    `rhs(state, inputs) -> dx/dt`; step k uses inputs[k]; row 0 is x0.
    """
    rule = STEP_RULES[Method.parse(method)]
    states = [x0]
    for k in range(inputs.shape[0] - 1):
        u = inputs[k]
        states.append(rule(lambda x: rhs(x, u), states[-1], dt))
    return torch.stack(states)


def run_steps(step: Callable[[torch.Tensor, torch.Tensor], torch.Tensor], x0: torch.Tensor,
              inputs: torch.Tensor) -> torch.Tensor:
    """States (T, B, 6) from a whole-step function `step(x (B, 6), u (B, 4)) -> x_next`,
    x0 (B, 6) and inputs (T, B, 4); row 0 is x0."""
    states = [x0]
    for k in range(inputs.shape[0] - 1):
        states.append(step(states[-1], inputs[k]))
    return torch.stack(states)
