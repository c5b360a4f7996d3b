"""One integration step of a force model as a module, and the step loop around it.

`Step` maps (state (B, 6), inputs (B, 4)) to the state one step of dt later with the
inputs held (Euler, classical RK4 or the 3/8 rule of `sysid.dynamics.integrators`): the unit that
`sysid.fast.compiled` compiles and `sysid.fast.export` exports. `Derivative` is the bare right-hand
side dx/dt (B, 6). `sysid.dynamics.integrators.run_steps` runs a step over recorded inputs;
`Rollout` runs up to a fixed number of steps inside one module (the same loop as
`sysid.dynamics.integrators.while_steps`, a `while_loop`), so a
compiled prediction is one native call instead of one per step.

Both evaluate the right-hand side through `sysid.dynamics.equations.lean_derivative` (the model's
force channels, no force breakdown). Numbers: `Step` with Euler is bit-identical to
torchdiffeq's Euler in `sysid.dynamics.equations.integrate` (x + dt f(x)); the Runge-Kutta rules
agree to round-off.
"""
from __future__ import annotations

import torch
from torch import nn

from sysid.config.choices import Method
from sysid.dynamics.equations import derivative_channels, lean_derivative
from sysid.dynamics.integrators import STEP_RULES, while_steps


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
            return lean_derivative(self.force_model, state.T, inputs.T, 0)
        return lean_derivative(self.force_model, state, inputs)

    def with_gate(self, state: torch.Tensor, inputs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor | None]:
        """(dx/dt (B, 6), the kNN gate's decision (B,): True where F_NN applies, None
        without a gate) at states (B, 6) with inputs (B, 4): one evaluation of the FNN and
        the gate where the model gives both (``gated_force_channels``), else the model's
        ``gate_decision`` beside the derivative. dx/dt equals `forward`'s."""
        eager_rate = getattr(self.force_model, "eager_rate", None) if not self.channels_first else None
        found = eager_rate(state, inputs) if eager_rate is not None else None
        if found is not None:  # one native call for F_MMG (`sysid.mmg.native`), no gradient
            return found
        gated = getattr(self.force_model, "gated_force_channels", None)
        if gated is None:
            decide = getattr(self.force_model, "gate_decision", None)
            return self(state, inputs), decide(state, inputs) if decide is not None else None
        force, _, on = gated(state, inputs)
        return torch.stack(derivative_channels(state, force, self.force_model.coefficients), -1), on


class Step(nn.Module):
    """x_{k+1} (B, 6) from x_k (B, 6) and inputs_k (B, 4) held over one step.

    Parameters
    ----------
    force_model : MMG, NN-only or hybrid model (with its kNN gate).
    method : the step rule.
    dt : step length [s].
    channels_first : states (6, B) and inputs (4, B) instead (see `Derivative`).
    """

    def __init__(self, force_model: nn.Module, method: Method, dt: float, channels_first: bool = False):
        super().__init__()
        self.force_model = force_model
        self.method = method
        self.dt = float(dt)
        self.channels_first = channels_first

    def forward(self, state: torch.Tensor, inputs: torch.Tensor) -> torch.Tensor:
        rule = STEP_RULES[self.method]
        if self.channels_first:
            u = inputs.T
            return rule(lambda x: lean_derivative(self.force_model, x.T, u, 0), state, self.dt).contiguous()
        return rule(lambda x: lean_derivative(self.force_model, x, inputs), state, self.dt)


class Rollout(nn.Module):
    """Up to `capacity` steps of a `Step` in one call, as one `while_loop`.

    ``forward(x0, inputs, steps)``: x0 (B, 6) (or (6, B) for a channels-first step),
    inputs (capacity, B, 4) (or (capacity, 4, B)), steps () int64 <= capacity, the number
    of steps to take (step k holds inputs[k]). Returns the states after steps 1..steps,
    (capacity, B, 6) (or (capacity, 6, B)), rows from `steps` on zero, and the last state
    (`sysid.dynamics.integrators.while_steps`: each state written into the record in place).
    """

    def __init__(self, step: Step, capacity: int):
        super().__init__()
        self.step = step
        self.capacity = int(capacity)

    def forward(self, x0: torch.Tensor, inputs: torch.Tensor, steps: torch.Tensor) -> torch.Tensor:
        states = torch.zeros((self.capacity, *x0.shape), dtype=x0.dtype, device=x0.device)

        def advance(k, x):
            x = self.step(x, inputs.index_select(0, k.reshape(1))[0])
            return x, x

        last = while_steps(advance, states, (x0,), steps)[1]
        return states, last  # the last state keeps the loop (and its writes) in the program
