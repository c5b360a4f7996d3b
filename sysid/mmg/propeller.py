"""Propeller forces in four quadrants (paper Eqs. 27-35; docs: MMG equations).

Q1: n >= 0, u >= 0 (standard MMG thrust); Q2: n >= 0, u < 0 (thrust plus lateral
polynomials in J_s); Q3/Q4: n < 0 (CMT reverse-rotation polynomials). n = 0 follows the
n >= 0 formulas, which give zero force.
"""
from __future__ import annotations

from typing import NamedTuple

import torch

from sysid.mmg.guards import SPEED_GUARD, TINY


class PropellerState(NamedTuple):
    """Intermediate propeller quantities, also needed by the rudder model."""

    one_minus_wP: torch.Tensor  # -, 1 - w_P, clipped to (0, 1]
    J_s: torch.Tensor           # -, u / (n D) (guarded)
    J: torch.Tensor             # -, advance ratio with wake for u >= 0
    K_T: torch.Tensor           # -, thrust coefficient the rudder sees (0 for n = 0)


def propeller_inflow(u, v, r, n, c) -> PropellerState:
    """Wake fraction, advance ratios and thrust coefficient.

    u, v [m/s], r [rad/s], n [rps]; `c` provides L_pp, D, w_P0, tau, C_P, x_P, k0..k2,
    C3, C6, C7, C10.
    """
    L = c.L_pp
    U = torch.sqrt(u * u + v * v)
    slow = U < SPEED_GUARD
    U_safe = torch.where(slow, torch.ones_like(U), U)
    tiny = torch.full_like(U, 1e-7)
    v_nd = torch.where(slow, tiny, v / U_safe)           # v'
    r_nd = torch.where(slow, tiny, r * L / U_safe)       # r'
    s = v_nd + c.x_P * r_nd                               # lateral inflow at the propeller
    w_P = c.w_P0 - c.tau * s.abs() - c.C_P * s * s
    one_minus_wP = torch.where(u > 0, 1.0 - w_P, torch.ones_like(w_P))
    one_minus_wP = torch.where(one_minus_wP > 1.0, torch.ones_like(one_minus_wP), one_minus_wP)
    one_minus_wP = torch.where(one_minus_wP <= 0.0, torch.full_like(one_minus_wP, TINY), one_minus_wP)

    n_stopped = n.abs() < TINY
    u_stopped = u.abs() < TINY
    nD = torch.where(n_stopped, torch.ones_like(n), n) * c.D
    J_s = torch.where(n_stopped, torch.sign(u) * 1e4,
                      torch.where(u_stopped, torch.full_like(u, TINY), u / nD))
    J = torch.where(u >= 0, J_s * one_minus_wP, J_s)
    K_T_ahead = c.k0 + c.k1 * J + c.k2 * J * J
    K_T_reverse = torch.where(J_s >= c.C10, c.C6 + c.C7 * J_s, c.C3 + 0.0 * J_s)
    K_T = torch.where(n > TINY, K_T_ahead, torch.where(n < -TINY, K_T_reverse, torch.zeros_like(J)))
    return PropellerState(one_minus_wP, J_s, J, K_T)


def propeller_force(u, v, r, n, c, inflow: PropellerState | None = None):
    """X_P [N], Y_P [N], N_P [N m] for any quadrant.

    `c` provides rho, L_pp, d, D, P, t_P, A1..A8, B1..B8 and what `propeller_inflow` needs.
    """
    if inflow is None:
        inflow = propeller_inflow(u, v, r, n, c)
    J_s = inflow.J_s
    L = c.L_pp
    q = 0.5 * c.rho * L * c.d
    n2 = n * n
    ahead = n >= 0
    astern_motion = u < 0
    thrust_scale = c.rho * n2 * c.D**4
    # n >= 0: K_T(J) with J = J_s for u < 0; n < 0: CMT reverse polynomial
    K_T_ahead = c.k0 + c.k1 * inflow.J + c.k2 * inflow.J * inflow.J
    X_P = torch.where(ahead, thrust_scale * (1.0 - c.t_P) * K_T_ahead, thrust_scale * inflow.K_T)
    # Q2 lateral polynomials (n P)^2
    nP2 = n2 * c.P**2
    Y_Q2 = q * nP2 * (c.A6 * J_s * J_s + c.A7 * J_s + c.A8)
    N_Q2 = q * L * nP2 * (c.B6 * J_s * J_s + c.B7 * J_s + c.B8)
    # reverse rotation, piecewise linear in J_s, (n D)^2
    nD2 = n2 * c.D**2
    low, high = J_s < -0.35, J_s > -0.06
    cY = torch.where(low, c.A3 + c.A4 * J_s, torch.where(high, c.A5 + 0.0 * J_s, c.A1 + c.A2 * J_s))
    cN = torch.where(low, c.B3 + c.B4 * J_s, torch.where(high, c.B5 + 0.0 * J_s, c.B1 + c.B2 * J_s))
    zero = torch.zeros_like(X_P)
    Y_P = torch.where(ahead, torch.where(astern_motion, Y_Q2, zero), q * nD2 * cY)
    N_P = torch.where(ahead, torch.where(astern_motion, N_Q2, zero), q * L * nD2 * cN)
    return X_P, Y_P, N_P
