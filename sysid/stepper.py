"""One integration step of a force model as a module, and the step loop around it.

`Step` maps (state (B, 6), inputs (B, 4)) to the state one step of dt later with the
inputs held (Euler, classical RK4 or the 3/8 rule of `sysid.integrators`): the unit that
`sysid.compiled` compiles and `sysid.export` exports. `Derivative` is the bare right-hand
side dx/dt (B, 6). `sysid.integrators.run_steps` runs a step over recorded inputs.

Numbers: `Step` with Euler is bit-identical to torchdiffeq's Euler in
`sysid.dynamics.integrate` (x + dt f(x)); the Runge-Kutta rules agree to round-off.
"""
from __future__ import annotations

import torch
from torch import nn

from sysid.dynamics import derivative
from sysid.integrators import STEP_RULES, Method


class Derivative(nn.Module):
    """dx/dt (B, 6) of a force model at states (B, 6) with inputs (B, 4).

    ``channels_first=True``: states (6, B), inputs (4, B), dx/dt (6, B) instead; each
    channel is then contiguous, which lets compiled code vectorize over the batch.
    """

    def __init__(self, force_model: nn.Module, channels_first: bool = False):
        super().__init__()
        self.force_model = force_model
        self.channels_first = channels_first

    def forward(self, state: torch.Tensor, inputs: torch.Tensor) -> torch.Tensor:
        if self.channels_first:
            return derivative(self.force_model, state.T, inputs.T).T.contiguous()
        return derivative(self.force_model, state, inputs)


class Step(nn.Module):
    """x_{k+1} (B, 6) from x_k (B, 6) and inputs_k (B, 4) held over one step.

    Parameters
    ----------
    force_model : MMG, NN-only or hybrid model (with its kNN gate).
    method : the step rule.
    dt : step length [s].
    channels_first : states (6, B) and inputs (4, B) instead (see `Derivative`).
    """

    def __init__(self, force_model: nn.Module, method: Method | str, dt: float, channels_first: bool = False):
        super().__init__()
        self.force_model = force_model
        self.method = Method.parse(method)
        self.dt = float(dt)
        self.channels_first = channels_first

    def forward(self, state: torch.Tensor, inputs: torch.Tensor) -> torch.Tensor:
        rule = STEP_RULES[self.method]
        if self.channels_first:
            u = inputs.T
            return rule(lambda x: derivative(self.force_model, x.T, u).T, state, self.dt).contiguous()
        return rule(lambda x: derivative(self.force_model, x, inputs), state, self.dt)
