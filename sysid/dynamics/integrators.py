"""The integrator choice, typed, and the fixed-step rules it names.

`Method` (`sysid.config.choices`) names the rule: explicit Euler (the paper's), classical RK4 (1/6, 1/3, 1/3, 1/6,
the lab simulator's) or torchdiffeq's own "rk4" (the 3/8 rule). `Integrator` adds how the
steps are run: through torchdiffeq's public `odeint` (differentiable; training), or the
same rule as one compiled function per step (`compiled=True`; inference, see
`sysid.fast.compiled.predict`). Classical RK4 has no public name in torchdiffeq, so it is written
here (`rk4_step`) instead of being registered in torchdiffeq's solver table.

Every step holds the inputs over the step (zero-order hold): a step is a function of the
state x (..., 6) and of one right-hand side f(x) -> dx/dt (..., 6), step length dt [s].
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Union

import torch

from sysid.config.choices import Method

RightHandSide = Callable[[torch.Tensor], torch.Tensor]  # f(x (..., 6)) -> dx/dt (..., 6)


@dataclass(frozen=True)
class Integrator:
    """How `sysid.dynamics.equations.integrate` steps the equations of motion.

    method : the step rule.
    compiled : run each step as one compiled function (`sysid.fast.compiled.predict`):
        inference only, no gradient, no force record; falls back to the eager step (same
        numbers) where compilation is unavailable. `sysid.dynamics.equations.integrate`, the
        differentiable path, refuses it.
    """

    method: Method = Method.EULER
    compiled: bool = False

    def __post_init__(self):
        object.__setattr__(self, "method", Method.parse(self.method))

    @classmethod
    def of(cls, value: "IntegratorLike") -> "Integrator":
        """An `Integrator` from an `Integrator`, a `Method` or a method name."""
        return value if isinstance(value, Integrator) else cls(Method.parse(value))


IntegratorLike = Union[Integrator, Method, str]


def euler_step(f: RightHandSide, x: torch.Tensor, dt: float) -> torch.Tensor:
    """x + dt f(x)."""
    return x + dt * f(x)


def rk4_step(f: RightHandSide, x: torch.Tensor, dt: float) -> torch.Tensor:
    """Classical fourth-order Runge-Kutta step (weights 1/6, 1/3, 1/3, 1/6)."""
    half = 0.5 * dt
    k1 = f(x)
    k2 = f(x + half * k1)
    k3 = f(x + half * k2)
    k4 = f(x + dt * k3)
    return x + (k1 + 2.0 * (k2 + k3) + k4) * (dt / 6.0)


def rk4_38_step(f: RightHandSide, x: torch.Tensor, dt: float) -> torch.Tensor:
    """Kutta's 3/8-rule fourth-order step (torchdiffeq's "rk4")."""
    third = dt / 3.0
    k1 = f(x)
    k2 = f(x + third * k1)
    k3 = f(x + dt * k2 - third * k1)
    k4 = f(x + dt * (k1 - k2 + k3))
    return x + (k1 + 3.0 * (k2 + k3) + k4) * (dt / 8.0)


STEP_RULES: dict[Method, Callable[[RightHandSide, torch.Tensor, float], torch.Tensor]] = {
    Method.EULER: euler_step, Method.RK4: rk4_step, Method.RK4_38: rk4_38_step}


def rollout(rhs: Callable[[torch.Tensor, torch.Tensor], torch.Tensor], x0: torch.Tensor,
            inputs: torch.Tensor, dt: float, method: Method) -> torch.Tensor:
    """States (T, ..., 6) from x0 (..., 6) and inputs (T, ..., 4) by a plain step loop.

    `rhs(state, inputs) -> dx/dt`; step k holds inputs[k]; row 0 is x0.
    """
    rule = STEP_RULES[method]
    states = [x0]
    for k in range(inputs.shape[0] - 1):
        u = inputs[k]
        states.append(rule(lambda x: rhs(x, u), states[-1], dt))  # noqa: B023 (called within this step)
    return torch.stack(states)


def run_steps(step: Callable[[torch.Tensor, torch.Tensor], torch.Tensor], x0: torch.Tensor,
              inputs: torch.Tensor) -> torch.Tensor:
    """States (T, B, 6) from a whole-step function `step(x (B, 6), u (B, 4)) -> x_next`,
    x0 (B, 6) and inputs (T, B, 4); row 0 is x0."""
    states = [x0]
    for k in range(inputs.shape[0] - 1):
        states.append(step(states[-1], inputs[k]))
    return torch.stack(states)
