"""Equations of motion (paper Eqs. 1, 4) and their integration with torchdiffeq.

`ShipDynamics` is the right-hand side f(t, x) of the 3-DOF maneuvering equations for any
force model (MMG, NN-only, hybrid) with zero-order-hold inputs; `integrate` runs many
trajectories at once through torchdiffeq's `odeint` (plain backprop, no adjoint).

Time inside the solver is counted in steps (tau = t / dt), so step k's input is
``inputs[floor(tau)]`` exactly, also at the perturbed end point of a Runge-Kutta step.
"""
from __future__ import annotations

from typing import Literal

import torch
from torch import nn
from torchdiffeq import odeint
from torchdiffeq._impl.odeint import SOLVERS as _TORCHDIFFEQ_SOLVERS
from torchdiffeq._impl.fixed_grid import RK4 as _RK4_3_8
from torchdiffeq._impl.rk_common import rk4_step_func

from sysid.mmg.breakdown import ForceBreakdown

Method = Literal["euler", "rk4", "rk4_3/8"]


class _ClassicalRK4(_RK4_3_8):
    """Classical RK4 (1/6, 1/3, 1/3, 1/6) as the lab's simulator uses; torchdiffeq's
    "rk4" is the 3/8 rule."""

    def _step_func(self, func, t0, dt, t1, y0):
        f0 = func(t0, y0)
        return rk4_step_func(func, t0, dt, t1, y0, f0=f0, perturb=self.perturb), f0


_TORCHDIFFEQ_SOLVERS.setdefault("rk4_classic", _ClassicalRK4)
_SOLVER_NAME = {"euler": "euler", "rk4": "rk4_classic", "rk4_3/8": "rk4"}
INTEGRATORS = ("euler", "rk4")  # what configs and the CLI offer: the paper's and the lab's


def body_acceleration(state: torch.Tensor, force: torch.Tensor, c) -> torch.Tensor:
    """(u_dot, v_dot, r_dot) (..., 3) from Eq. (4).

    state (..., 6) = (x, u, y, v, psi, r); force (..., 3) = (X, Y, N) [N, N, N m];
    `c` provides m, m_x, m_y, I_zz_J_zz [kg, kg m^2] and x_G [m].
    """
    u, v, r = state[..., 1], state[..., 3], state[..., 5]
    X, Y, N = force.unbind(-1)
    m, xG = c.m, c.x_G
    mxG = m * xG
    u_dot = (X + (m + c.m_y) * v * r + mxG * r * r) / (m + c.m_x)
    # [[m+m_y, x_G m], [x_G m, I+J+x_G^2 m]] (v_dot, r_dot) = (Y - (m+m_x) u r, N - x_G m u r)
    a11, a12, a22 = m + c.m_y, mxG, c.I_zz_J_zz + xG * xG * m
    b1 = Y - (m + c.m_x) * u * r
    b2 = N - mxG * u * r
    det = a11 * a22 - a12 * a12
    v_dot = (a22 * b1 - a12 * b2) / det
    r_dot = (a11 * b2 - a12 * b1) / det
    return torch.stack((u_dot, v_dot, r_dot), -1)


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


def state_derivative(state: torch.Tensor, force: torch.Tensor, c) -> torch.Tensor:
    """dx/dt (..., 6) = (x_dot, u_dot, y_dot, v_dot, psi_dot, r_dot), Eqs. (1) and (4)."""
    u, v, psi, r = state[..., 1], state[..., 3], state[..., 4], state[..., 5]
    acc = body_acceleration(state, force, c)
    cos_psi, sin_psi = torch.cos(psi), torch.sin(psi)
    x_dot = u * cos_psi - v * sin_psi
    y_dot = u * sin_psi + v * cos_psi
    return torch.stack((x_dot, acc[..., 0], y_dot, acc[..., 1], r, acc[..., 2]), -1)


def compiled_derivative(force_model: nn.Module):
    """torch.compile'd (state, inputs) -> dx/dt of a force model, cached on the model.

    Compiling costs tens of seconds once; afterwards a batch-1 call is about ten times
    cheaper than eager (benchmarks/mmg_speed.py). Suits long-lived processes (a controller).
    """
    fn = force_model.__dict__.get("_compiled_derivative")
    if fn is None:
        def derivative(state, inputs):
            forces = force_model(state, inputs)
            return state_derivative(state, forces.total, force_model.coefficients)
        fn = torch.compile(derivative, dynamic=False)
        force_model.__dict__["_compiled_derivative"] = fn
    return fn


class ShipDynamics(nn.Module):
    """Right-hand side f(tau, x) with zero-order-hold inputs, in step time tau = t / dt.

    Parameters
    ----------
    force_model : module mapping (state (..., 6), inputs (..., 4)) to a `ForceBreakdown`;
        it carries ``coefficients`` with the mass terms.
    inputs : (T, ..., 4) inputs; step k uses ``inputs[k]``.
    dt : step length [s].
    """

    def __init__(self, force_model: nn.Module, inputs: torch.Tensor, dt: float, compiled: bool = False,
                 record: list | None = None):
        super().__init__()
        self.record = record
        self.force_model = force_model
        self.inputs = inputs
        self.dt = float(dt)
        self._compiled = compiled_derivative(force_model) if compiled else None

    def derivative(self, state: torch.Tensor, inputs: torch.Tensor) -> tuple[torch.Tensor, ForceBreakdown]:
        forces = self.force_model(state, inputs)
        return state_derivative(state, forces.total, self.force_model.coefficients), forces

    def forward(self, tau: torch.Tensor, state: torch.Tensor) -> torch.Tensor:
        k = min(max(int(tau), 0), self.inputs.shape[0] - 1)  # tau >= 0: int() is floor
        if self._compiled is not None and self.record is None:
            return self.dt * self._compiled(state, self.inputs[k])
        derivative, forces = self.derivative(state, self.inputs[k])
        if self.record is not None:
            self.record.append(forces)
        return self.dt * derivative


def integrate(force_model: nn.Module, x0: torch.Tensor, inputs: torch.Tensor, dt: float,
              method: Method = "euler", compiled: bool = False,
              record: list | None = None) -> torch.Tensor:
    """Predict trajectories from x0 with recorded inputs held over each step.

    Parameters
    ----------
    force_model : MMG, NN-only or hybrid force model.
    x0 : (..., 6) initial states (any batch shape).
    inputs : (T, ..., 4) inputs on the time grid; step k (t_k -> t_k+1) uses inputs[k],
        the last row is not used.
    dt : grid step [s].
    method : "euler" (the paper's), "rk4" (classical, the lab simulator's) or "rk4_3/8"
        (torchdiffeq's own rk4).
    compiled : use the torch.compile'd right-hand side (see `compiled_derivative`).
    record : a list to which each right-hand-side call appends its `ForceBreakdown`; with
        "euler" that is one entry per step, at the states the step started from.

    Returns
    -------
    (T, ..., 6) states at t_0 .. t_{T-1}; row 0 is x0.
    """
    if method not in _SOLVER_NAME:
        raise ValueError(f"integrator {method!r}: choose one of {sorted(_SOLVER_NAME)}")
    if inputs.shape[1:-1] != x0.shape[:-1]:
        raise ValueError(f"inputs {tuple(inputs.shape)} do not match x0 {tuple(x0.shape)}: expected (T, *batch, 4)")
    steps = inputs.shape[0]
    tau = torch.arange(steps, dtype=x0.dtype, device=x0.device)
    rhs = ShipDynamics(force_model, inputs, dt, compiled, record)
    options = {"perturb": True} if method != "euler" else None
    return odeint(rhs, x0, tau, method=_SOLVER_NAME[method], options=options)
