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
from typing import Any, Callable, Union

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

    def __post_init__(self):  # the public constructor takes a rule's name too: ``Integrator("rk4")``
        object.__setattr__(self, "method", Method.parse(self.method))

    @classmethod
    def of(cls, value: "IntegratorLike") -> "Integrator":
        """An `Integrator` from an `Integrator`, a `Method` or a method name: the public entry
        points (`sysid.dynamics.equations.integrate`, `sysid.fast.compiled.predict`) call it
        once; the layers below take the `Integrator` or its `Method`."""
        return value if isinstance(value, Integrator) else cls(value)  # type: ignore[arg-type]


IntegratorLike = Union[Integrator, Method, str]
EULER = Integrator(Method.EULER)  # the paper's rule, eager: the default of the layers below the public entries


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


Advance = Callable[[int, Any], tuple[torch.Tensor, Any]]  # (step k, carry) -> (record row k, carry after)


def step_loop(advance: Advance, carry: Any, steps: int) -> list[torch.Tensor]:
    """The rows of `steps` calls of ``advance(k, carry) -> (row, carry)``, k = 0 .. steps-1,
    each from the carry the one before left: the one eager loop of every rollout (recorded
    inputs, `rollout` and `run_steps`; closed loop, `sysid.maneuvers.closed_loop.run_eager`).
    Its in-program twin, for compiled code, is `while_steps`."""
    rows = []
    for k in range(steps):
        row, carry = advance(k, carry)
        rows.append(row)
    return rows


def while_steps(advance: Callable[..., tuple], record: torch.Tensor, carry: tuple, steps: torch.Tensor) -> tuple:
    """`step_loop` inside one program: ``advance(k, *carry) -> (row, *carry)`` for k = 0 ..
    steps-1 (k and steps () int64 tensors) as one `torch.while_loop`, row k written into
    `record[k]` in place (a record carried through the loop would be copied, and allocated
    anew, on every step). Returns the loop's final (k, *carry); callers return a part of it
    beside the record, which keeps the loop and its writes in the captured program."""
    k0 = torch.zeros((), dtype=torch.int64, device=record.device)

    def more(k, *state):
        return k < steps

    def body(k, *state):
        row, *after = advance(k, *state)
        record.index_copy_(0, k.reshape(1), row[None])
        return (k + 1, *after)

    return torch.while_loop(more, body, (k0, *carry))


def run_in_chunks(call: Callable[[Any, int, int], tuple[torch.Tensor, Any]], carry: Any, steps: int,
                  capacity: int, head: torch.Tensor | None = None) -> torch.Tensor:
    """The one driver of compiled loops of `capacity` steps: ``call(carry, done, n) -> (rows
    (n, ...), carry after them)`` for n = `capacity` steps at a time (fewer in the last
    call) until `steps` are done, each call from the carry the one before left. Returns the
    rows of every call concatenated, after `head` (e.g. the start state) where given."""
    parts = [] if head is None else [head]
    done = 0
    while done < steps:
        n = min(capacity, steps - done)
        rows, carry = call(carry, done, n)
        parts.append(rows)
        done += n
    return torch.cat(parts)


def rollout(rhs: Callable[[torch.Tensor, torch.Tensor], torch.Tensor], x0: torch.Tensor,
            inputs: torch.Tensor, dt: float, method: Method) -> torch.Tensor:
    """States (T, ..., 6) from x0 (..., 6) and inputs (T, ..., 4) by `method`'s step rule on
    `rhs(state, inputs) -> dx/dt`; step k holds inputs[k]; row 0 is x0."""
    rule = STEP_RULES[method]
    return run_steps(lambda x, u: rule(lambda y: rhs(y, u), x, dt), x0, inputs)


def run_steps(step: Callable[[torch.Tensor, torch.Tensor], torch.Tensor], x0: torch.Tensor,
              inputs: torch.Tensor) -> torch.Tensor:
    """States (T, B, 6) from a whole-step function `step(x (B, 6), u (B, 4)) -> x_next`,
    x0 (B, 6) and inputs (T, B, 4) (`step_loop`); row 0 is x0."""

    def advance(k: int, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        following = step(x, inputs[k])
        return following, following
    return torch.stack([x0, *step_loop(advance, x0, inputs.shape[0] - 1)])
