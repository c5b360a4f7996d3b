"""Constructed MMG rows for the Esso Osaka that take every branch of its force families, rows
on the switches, and the autograd reference of the hybrid's MMG right-hand side (shared by
the hand-derived VJP's and the native kernel's tests)."""
from __future__ import annotations

import torch

from sysid.dynamics.equations import state_derivative
from sysid.hybrid.correction import correction_inputs
from sysid.mmg.model import MMG
from sysid.mmg.ship import load_ship

ESSO = MMG(load_ship("esso_osaka"))


def rows_of(values) -> tuple[torch.Tensor, torch.Tensor]:
    """(state (N, 6), inputs (N, 4)) from rows (u, v, psi, r, n, delta, U_T, zeta)."""
    a = torch.tensor(values, dtype=torch.float64)
    zero = torch.zeros(len(a), dtype=torch.float64)
    state = torch.stack([zero + 1.5, a[:, 0], zero - 2.0, a[:, 1], a[:, 2], a[:, 3]], -1)
    return state, a[:, 4:]


def branch_rows() -> tuple[torch.Tensor, torch.Tensor]:
    """Rows away from every switch that take each branch of every family (checked in
    `tests/mmg/test_vjp.py::test_the_rows_take_every_branch`)."""
    D = float(ESSO.coefficients.D)
    C10 = float(ESSO.coefficients.C10)
    rows = [
        (0.9, 0.05, 0.3, 0.01, 10.0, 0.2, 5.0, 1.0),      # ahead, ahead revolutions (Yoshimura inflow)
        (0.6, -0.04, -1.2, -0.02, 8.0, -0.3, 3.0, 4.0),
        (-0.5, 0.03, 0.5, -0.01, 6.0, -0.3, 4.0, 2.0),    # astern motion, ahead revolutions (Q2)
        (0.004, 0.002, 0.7, 0.3, 9.0, 0.1, 2.0, 5.5),     # cross-flow crossing (|v| < |b| L/2)
        (0.02, -0.001, 2.5, -0.25, 7.0, 0.35, 6.0, 0.3),
        (0.3, 0.6, 0.1, 0.02, 5.0, 0.0, 1.0, 3.0),        # large drift
        (0.1, 0.01, 0.1, 0.3, 5.0, 0.05, 1.0, 3.0),       # large r' at the propeller: 1 - w_P clamped
        (0.7, -0.5, -0.4, 0.05, 4.0, -0.1, 2.5, 1.7),
        (0.8, 0.05, 0.2, 0.01, 0.0, 0.2, 4.0, 0.5),       # n = 0: no thrust
        (0.9, 0.02, 0.4, 0.0, 0.5, -0.2, 3.0, 2.2),       # K_T <= 0 ahead (large J): Kitagawa inflow
        (0.5, 0.02, 1.0, 0.01, 0.0 - 1.5, 0.25, 0.0, 0.0),  # reverse revolutions, calm
        (0.05, 0.02, 1.0, 0.01, -12.0, 0.25, 3.0, 1.0),   # reverse, strong race: Kitagawa s < 0
        (-0.6, -0.02, -2.0, 0.02, -6.0, 0.3, 5.0, 4.0),   # astern with reverse revolutions: u_R = u
    ]
    # reverse revolutions on each piece of the lateral lines (J_s < -0.35, between, > -0.06)
    # and on each side of C10 (J_s of either sign)
    for J_s in (-0.6, -0.2, -0.03, C10 + 0.05 if C10 < 0 else C10 - 0.05, C10 + 0.1, 0.4):
        u = 0.4 if J_s < 0 else -0.4
        rows.append((u, 0.03, 0.8, -0.01, u / (J_s * D), 0.15, 2.0, 2.5))
    return rows_of(rows)


def switch_rows() -> tuple[torch.Tensor, torch.Tensor]:
    """Rows on switches: u = 0, v + x_R r = 0, n = 0 astern, the speed guard's inside, calm."""
    x_R = float(ESSO.coefficients.x_R)
    return rows_of([
        (0.0, 0.3, 0.2, 0.01, 5.0, 0.1, 3.0, 1.0),
        (0.0, -0.2, 0.2, -0.02, -5.0, 0.1, 3.0, 1.0),
        (0.5, -x_R * 0.04, 0.4, 0.04, 6.0, 0.2, 3.0, 2.0),
        (-0.3, 0.01, 0.4, 0.01, 0.0, 0.2, 3.0, 2.0),
        (4e-6, 3e-6, 0.4, 0.01, 3.0, 0.2, 3.0, 2.0),
        (0.4, 0.01, 0.4, 0.01, 3.0, 0.2, 0.0, 2.0),
    ])


def reference(state, inputs, mmg=ESSO):
    """(dx/dt of F_MMG, F_MMG, s) through autograd over the MMG, `correction_inputs` and the
    equations of motion (the path training took before)."""
    force, wind, _ = mmg.total_force(state, inputs)
    rate = state_derivative(state, force, mmg.coefficients)
    return torch.cat([rate, force, correction_inputs(state, inputs, torch.cat(wind, -1))], -1)
