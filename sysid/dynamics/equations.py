"""Equations of motion (paper Eqs. 1, 4) and their integration.

`ShipDynamics` is the right-hand side f(t, x) of the 3-DOF maneuvering equations for any
force model (MMG, NN-only, hybrid) with zero-order-hold inputs; `integrate` runs many
trajectories at once, differentiably, with the rule a `Method` names: torchdiffeq's public
`odeint` (Euler, the 3/8 rule; plain backprop, no adjoint) or a plain step loop (classical
RK4, which torchdiffeq's public names lack); `eager_predict` is the same without gradient.
Compiled prediction: `sysid.fast.compiled.predict` (which falls back to `eager_predict`).

Time inside torchdiffeq is counted in steps (tau = t / dt), so step k's input is
``inputs[floor(tau)]`` exactly, also at the perturbed end point of a Runge-Kutta step.
"""
from __future__ import annotations

from dataclasses import dataclass, fields

import torch
from torch import nn

from sysid.dynamics.integrators import EULER, Integrator, IntegratorLike, Method, rollout
from sysid.mmg.capture import captured
from sysid.mmg.coefficient_lookup import Rows, coefficient_matrix, view_of
from sysid.mmg.model import ForceBreakdown
from sysid.mmg.vjp import RATE_ROWS

_ODEINT_NAME = {Method.EULER: "euler", Method.RK4_38: "rk4"}  # torchdiffeq's public names


def acceleration_channels(u, v, r, X, Y, N, c):
    """(u_dot, v_dot, r_dot), each (...,), from Eq. (4) for u, v [m/s], r [rad/s] and
    X, Y [N], N [N m], each (...,); `c` provides m, m_x, m_y, I_zz_J_zz [kg, kg m^2], x_G [m]."""
    c = view_of(c, u)
    m_x, m_y, mxG = c.m_plus_mx, c.m_plus_my, c.mxG  # m + m_x, m + m_y, m x_G
    u_dot = (X + m_y * v * r + mxG * r * r) / m_x
    # [[m+m_y, x_G m], [x_G m, I+J+x_G^2 m]] (v_dot, r_dot) = (Y - (m+m_x) u r, N - x_G m u r)
    a11, a12, a22, det = m_y, mxG, c.a22, c.det
    b1 = Y - m_x * u * r
    b2 = N - mxG * u * r
    v_dot = (a22 * b1 - a12 * b2) / det
    r_dot = (a11 * b2 - a12 * b1) / det
    return u_dot, v_dot, r_dot


def body_acceleration(state: torch.Tensor, force: torch.Tensor, c) -> torch.Tensor:
    """(u_dot, v_dot, r_dot) (..., 3) from Eq. (4).

    state (..., 6) = (x, u, y, v, psi, r); force (..., 3) = (X, Y, N) [N, N, N m];
    `c` provides m, m_x, m_y, I_zz_J_zz [kg, kg m^2] and x_G [m].
    """
    return torch.stack(acceleration_channels(state[..., 1], state[..., 3], state[..., 5], *force.unbind(-1), c), -1)  # type: ignore[call-arg]


def required_force(state: torch.Tensor, acceleration: torch.Tensor, c) -> torch.Tensor:
    """(X, Y, N) (..., 3) [N, N, N m] that produces `acceleration` = (u_dot, v_dot, r_dot)
    in Eq. (4): the inverse of `body_acceleration`."""
    u, v, r = state[..., 1], state[..., 3], state[..., 5]
    du, dv, dr = acceleration.unbind(-1)
    m, xG = c.m, c.x_G
    X = (m + c.m_x) * du - (m + c.m_y) * v * r - xG * m * r * r
    Y = (m + c.m_y) * dv + (m + c.m_x) * u * r + xG * m * dr
    N = (c.I_zz_J_zz + xG * xG * m) * dr + xG * m * (dv + u * r)
    return torch.stack((X, Y, N), -1)


def derivative_channels(state: torch.Tensor, force, c) -> tuple[torch.Tensor, ...]:
    """(x_dot, u_dot, y_dot, v_dot, psi_dot, r_dot), each (...,), Eqs. (1) and (4), from
    state (..., 6) and force = (X, Y, N), each (...,) [N, N, N m]."""
    _, u, _, v, psi, r = state.unbind(-1)
    u_dot, v_dot, r_dot = acceleration_channels(u, v, r, *force, c)  # type: ignore[call-arg]
    cos_psi, sin_psi = torch.cos(psi), torch.sin(psi)
    x_dot = u * cos_psi - v * sin_psi
    y_dot = u * sin_psi + v * cos_psi
    return x_dot, u_dot, y_dot, v_dot, r, r_dot


# dx/dt (..., 6) as features (..., 16) times a (16, 6) matrix of the mass terms: features
# (X, Y, N, u r, v r, r r, u cos psi, u sin psi, v cos psi, v sin psi, x, u, y, v, psi, r)
_RATE = RATE_ROWS


def motion_rate(state: torch.Tensor, forces, motion, c) -> torch.Tensor:
    """dx/dt (..., 6), Eqs. (1) and (4), from state (..., 6), the force components, each
    (..., 3) = (X, Y, N) [N, N, N m] (summed in the product), and the forward's
    `sysid.mmg.motion.Motion` (u, v, psi, r as (..., 1), constants): one product with a
    matrix of the mass terms (`derived_constants`' ``eom_*``)."""
    coriolis = state[..., 1::2] * motion.r                        # (u r, v r, r r)
    cos_sin = torch.sin(motion.psi + motion.k.cos_sin_phase)      # (cos psi, sin psi)
    features = torch.cat([*forces, coriolis, motion.u * cos_sin, motion.v * cos_sin, state], -1)
    return features @ _rate_matrix(c, len(forces), state)


_RATES = {count: Rows(_RATE[:3] * count + _RATE[3:]) for count in range(1, 6)}  # by number of components


def _rate_matrix(c, components: int, like: torch.Tensor) -> torch.Tensor:
    return coefficient_matrix(c, _RATES[components], like)


def state_derivative(state: torch.Tensor, force: torch.Tensor, c) -> torch.Tensor:
    """dx/dt (..., 6) = (x_dot, u_dot, y_dot, v_dot, psi_dot, r_dot), Eqs. (1) and (4)."""
    return torch.stack(derivative_channels(state, force.unbind(-1), c), -1)


def derivative(force_model: nn.Module, state: torch.Tensor, inputs: torch.Tensor) -> torch.Tensor:
    """dx/dt (..., 6) of any force model at state (..., 6) with inputs (..., 4) (through
    `lean_derivative`: the same numbers as from the model's `ForceBreakdown`)."""
    return lean_derivative(force_model, state, inputs)


def lean_derivative(force_model: nn.Module, state: torch.Tensor, inputs: torch.Tensor, dim: int = -1) -> torch.Tensor:
    """`derivative` through the model's ``force_channels`` (X, Y, N as separate tensors, no
    force breakdown) where it has one: the same numbers with fewer, larger operations
    (what compiled steps run). dx/dt is stacked along `dim` (0: channels first, (6, ...))."""
    last = dim == -1 or dim == state.dim() - 1
    eager_rate = getattr(force_model, "eager_rate", None) if last else None
    found = eager_rate(state, inputs) if eager_rate is not None else None
    if found is not None:  # no gradient, the native kernel's families: one native call for F_MMG
        return found[0]
    identified_rate = getattr(force_model, "identified_rate", None) if last else None
    rate = identified_rate(state, inputs) if identified_rate is not None else None
    if rate is not None:  # an MMG identifying hull coefficients: their VJP by hand (`sysid.mmg.vjp`)
        return rate
    rate_terms = getattr(force_model, "rate_terms", None)
    if rate_terms is not None and last and not captured():
        return motion_rate(state, *rate_terms(state, inputs))  # one product for the equations of motion (eager)
    channels = getattr(force_model, "force_channels", None)
    force = channels(state, inputs)[0] if channels is not None else force_model(state, inputs).total.unbind(-1)
    return torch.stack(derivative_channels(state, force, force_model.coefficients), dim)


class ShipDynamics(nn.Module):
    """Right-hand side f(tau, x) with zero-order-hold inputs, in step time tau = t / dt.

    Parameters
    ----------
    force_model : module mapping (state (..., 6), inputs (..., 4)) to a `ForceBreakdown`;
        it carries ``coefficients`` with the mass terms.
    inputs : (T, ..., 4) inputs; step k uses ``inputs[k]``.
    dt : step length [s].
    record : optional list; each call appends the `ForceBreakdown` it computed.
    """

    def __init__(self, force_model: nn.Module, inputs: torch.Tensor, dt: float, record: list | None = None):
        super().__init__()
        self.record = record
        self.force_model = force_model
        self.inputs = inputs
        self.dt = float(dt)

    def derivative(self, state: torch.Tensor, inputs: torch.Tensor) -> tuple[torch.Tensor, ForceBreakdown]:
        forces = self.force_model(state, inputs)
        if self.record is not None:
            self.record.append(forces)
        return state_derivative(state, forces.total, self.force_model.coefficients), forces

    def rate(self, state: torch.Tensor, inputs: torch.Tensor) -> torch.Tensor:
        """dx/dt (..., 6): without a record, by `lean_derivative` (the same numbers, fewer
        operations: no force breakdown is built)."""
        if self.record is None:
            return lean_derivative(self.force_model, state, inputs)
        return self.derivative(state, inputs)[0]

    def forward(self, tau: torch.Tensor, state: torch.Tensor) -> torch.Tensor:
        k = min(max(int(tau), 0), self.inputs.shape[0] - 1)  # tau >= 0: int() is floor
        return self.dt * self.rate(state, self.inputs[k])


def check_shapes(x0: torch.Tensor, inputs: torch.Tensor) -> None:
    """ValueError unless x0 is (..., 6) and inputs (T, ..., 4) with the same batch shape."""
    if x0.shape[-1:] != (6,) or inputs.shape[-1:] != (4,) or inputs.shape[1:-1] != x0.shape[:-1]:
        raise ValueError(f"inputs {tuple(inputs.shape)} do not match x0 {tuple(x0.shape)}: "
                         "expected x0 (*batch, 6) and inputs (T, *batch, 4)")


def integrate(force_model: nn.Module, x0: torch.Tensor, inputs: torch.Tensor, dt: float,
              method: IntegratorLike = Method.EULER, *, record: list | None = None) -> torch.Tensor:
    """Predict trajectories from x0 with recorded inputs held over each step.

    Parameters
    ----------
    force_model : MMG, NN-only or hybrid force model.
    x0 : (..., 6) initial states (any batch shape).
    inputs : (T, ..., 4) inputs on the time grid; step k (t_k -> t_k+1) uses inputs[k],
        the last row is not used.
    dt : grid step [s].
    method : an `Integrator`, or a `Method` or its name: "euler" (the paper's), "rk4"
        (classical, the lab simulator's) or "rk4_3/8" (torchdiffeq's own rk4).
        (A compiled `Integrator` is for `sysid.fast.compiled.predict`, which has no gradient.)
    record : a list to which each right-hand-side call appends its `ForceBreakdown`; with
        "euler" that is one entry per step, at the states the step started from
        (`integrate_with_forces` returns them stacked instead).

    Returns
    -------
    (T, ..., 6) states at t_0 .. t_{T-1}; row 0 is x0.
    """
    integrator = Integrator.of(method)
    check_shapes(x0, inputs)
    if integrator.compiled:
        raise ValueError("integrate is the differentiable path: predict with a compiled "
                         "integrator through sysid.fast.compiled.predict")
    rhs = ShipDynamics(force_model, inputs, dt, record)
    if integrator.method not in _ODEINT_NAME:  # classical RK4: a plain step loop
        return rollout(rhs.rate, x0, inputs, dt, integrator.method)
    from torchdiffeq import odeint  # here: its import loads scipy.integrate (about 0.4 s), which eager
    # maneuvers and predictions (step loops) never need
    tau = torch.arange(inputs.shape[0], dtype=x0.dtype, device=x0.device)
    options = {"perturb": True} if integrator.method is not Method.EULER else None
    return odeint(rhs, x0, tau, method=_ODEINT_NAME[integrator.method], options=options)


def eager_predict(force_model: nn.Module, x0: torch.Tensor, inputs: torch.Tensor, dt: float,
                  integrator: Integrator = EULER) -> torch.Tensor:
    """States (T, ..., 6) predicted from x0 (..., 6) with inputs (T, ..., 4), no gradient:
    `integrate` under ``torch.no_grad()``. A compiled `Integrator` is refused here (it is
    `sysid.fast.compiled.predict`'s)."""
    with torch.no_grad():
        return integrate(force_model, x0, inputs, dt, integrator)


@dataclass
class Trajectory:
    """Predicted states (T, ..., 6) and the forces of every right-hand-side call, stacked:
    a `ForceBreakdown` of (S, ..., 3) tensors (S = T - 1 with Euler: the forces at the
    state each step started from)."""

    states: torch.Tensor
    forces: ForceBreakdown


def stack_forces(calls: list[ForceBreakdown]) -> ForceBreakdown:
    """One `ForceBreakdown` whose fields stack those of `calls` along a new first axis."""
    stacked = {}
    for f in fields(ForceBreakdown):
        values = [getattr(c, f.name) for c in calls]
        stacked[f.name] = None if any(v is None for v in values) else torch.stack(values)
    return ForceBreakdown(**stacked)


class TrainingDynamics(nn.Module):
    """Right-hand side f(tau, x) = dt `rate`(x, inputs[floor(tau)]) of a training rollout;
    `rate` (a force model's ``training_rate``) gives (dx/dt, F_NN, F_MMG), and each call's
    F_NN and F_MMG are kept in ``f_nn`` and ``f_mmg`` (the output penalty's). Where dt in the
    rate's dtype is 1 (dt = 1 s; a recorded grid's 0.99999999999998 s rounds to 1 in float32)
    the rate itself: the product with 1 is exact, so the same numbers with one operation and
    one autograd node fewer per step."""

    def __init__(self, rate, inputs: torch.Tensor, dt: float):
        super().__init__()
        self.rate = rate
        self.inputs = inputs
        self.dt = float(dt)
        self._dt: dict[torch.dtype, torch.Tensor | None] = {}  # dt as a 0-d tensor of the rate's dtype (None: 1)
        self.f_nn: list[torch.Tensor] = []
        self.f_mmg: list[torch.Tensor] = []

    def forward(self, tau: torch.Tensor, state: torch.Tensor) -> torch.Tensor:
        k = min(max(int(tau), 0), self.inputs.shape[0] - 1)
        rate, f_nn, f_mmg = self.rate(state, self.inputs[k])
        self.f_nn.append(f_nn)
        self.f_mmg.append(f_mmg)
        if rate.dtype not in self._dt:  # the same product as with the number dt, without converting it at every call
            dt = torch.tensor(self.dt, dtype=rate.dtype, device=rate.device)
            self._dt[rate.dtype] = None if bool(dt == 1) else dt
        dt = self._dt[rate.dtype]
        return rate if dt is None else rate * dt


def integrate_training(force_model: nn.Module, x0: torch.Tensor, inputs: torch.Tensor, dt: float,
                       fast: bool = True) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Euler rollouts of the training loss (torchdiffeq's `odeint`, plain backprop): states
    (T, ..., 6) from x0 (..., 6) with inputs (T, ..., 4), and F_NN, F_MMG (T - 1, ..., 3) of
    every step (zeros where a model has no such term).

    Through the model's ``training_rate`` where it has one that applies (one autograd
    Function with a hand-derived VJP for the MMG part: `sysid.mmg.vjp`); otherwise, or
    with ``fast=False``, through `integrate_with_forces` (autograd over every operation).
    The same numbers either way, to round-off.
    """
    training_rate = getattr(force_model, "training_rate", None) if fast else None
    rate = training_rate() if training_rate is not None else None
    if rate is None:
        trajectory = integrate_with_forces(force_model, x0, inputs, dt, Method.EULER)
        return trajectory.states, trajectory.forces.correction, trajectory.forces.mmg
    return _training_rollout(rate, x0, inputs, dt)


def integrate_loss(force_model: nn.Module, x0: torch.Tensor, inputs: torch.Tensor, dt: float) -> torch.Tensor:
    """States (T, ..., 6) of Euler rollouts from x0 (..., 6) with inputs (T, ..., 4) for a loss
    without forces: with gradients on, through the model's ``training_rate`` where it has one
    that applies (`integrate_training`'s rollout, its forces dropped), else `integrate`. The
    same numbers either way, to round-off."""
    training_rate = getattr(force_model, "training_rate", None) if torch.is_grad_enabled() else None
    rate = training_rate() if training_rate is not None else None
    if rate is None:
        return integrate(force_model, x0, inputs, dt, Method.EULER)
    return _training_rollout(rate, x0, inputs, dt)[0]


def _training_rollout(rate, x0: torch.Tensor, inputs: torch.Tensor, dt: float):
    """`integrate_training`'s rollout through `rate` (a ``training_rate``)."""
    check_shapes(x0, inputs)
    if inputs.shape[0] < 2:
        raise ValueError("no steps: inputs need at least two rows")
    from torchdiffeq import odeint  # here, as in `integrate`
    rhs = TrainingDynamics(rate, inputs.contiguous(), dt)  # each step's inputs one contiguous slice
    tau = torch.arange(inputs.shape[0], dtype=x0.dtype, device=x0.device)
    states = odeint(rhs, x0, tau, method=_ODEINT_NAME[Method.EULER])
    return states, torch.stack(rhs.f_nn), torch.stack(rhs.f_mmg)


def integrate_with_forces(force_model: nn.Module, x0: torch.Tensor, inputs: torch.Tensor, dt: float,
                          method: Method = Method.EULER) -> Trajectory:
    """`integrate` (not compiled) that also returns every call's forces, stacked.

    With Euler it is the training loss's rollout through autograd (`integrate_training`
    falls back to it): states from torchdiffeq's `odeint`, F_NN and F_MMG of each step for
    the output penalty (paper Eq. 17).
    """
    record: list[ForceBreakdown] = []
    states = integrate(force_model, x0, inputs, dt, method, record=record)
    if not record:
        raise ValueError("no steps: inputs need at least two rows")
    return Trajectory(states, stack_forces(record))
