"""Propeller forces in four quadrants (paper Eqs. 27-35; docs: MMG equations).

Q1: n >= 0, u >= 0 (standard MMG thrust); Q2: n >= 0, u < 0 (thrust plus lateral
polynomials in J_s); Q3/Q4: n < 0 (CMT reverse-rotation polynomials). n = 0 follows the
n >= 0 formulas, which give zero force.
"""
from __future__ import annotations

from typing import NamedTuple

import torch

from sysid.mmg.coefficients import coefficient_vector, view_of
from sysid.mmg.guards import SPEED_GUARD, TINY


class PropellerState(NamedTuple):
    """Intermediate propeller quantities, also needed by the rudder model."""

    one_minus_wP: torch.Tensor  # -, 1 - w_P, clipped to (0, 1]
    J_s: torch.Tensor           # -, u / (n D) (guarded)
    J: torch.Tensor             # -, advance ratio with wake for u >= 0
    K_T: torch.Tensor           # -, thrust coefficient the rudder sees (0 for n = 0)
    K_T_ahead: torch.Tensor | None = None  # -, K_T(J) of ahead revolutions, where computed


def propeller_inflow(u, v, r, n, c) -> PropellerState:
    """Wake fraction, advance ratios and thrust coefficient.

    u, v [m/s], r [rad/s], n [rps]; `c` provides L_pp, D, w_P0, tau, C_P, x_P, k0..k2,
    C3, C6, C7, C10.
    """
    c = view_of(c, u)
    L = c.L_pp
    U = torch.hypot(u, v)
    slow = U < SPEED_GUARD
    U_safe = torch.where(slow, 1.0, U)
    v_nd = torch.where(slow, 1e-7, v / U_safe)           # v'
    r_nd = torch.where(slow, 1e-7, r * L / U_safe)       # r'
    s = v_nd + c.x_P * r_nd                               # lateral inflow at the propeller
    w_P = c.w_P0 - c.tau * s.abs() - c.C_P * s * s
    one_minus_wP = torch.where(u > 0, 1.0 - w_P, 1.0).clamp(max=1.0)
    one_minus_wP = torch.where(one_minus_wP <= 0.0, TINY, one_minus_wP)

    n_stopped = n.abs() < TINY
    u_stopped = u.abs() < TINY
    nD = torch.where(n_stopped, 1.0, n) * c.D
    J_s = torch.where(n_stopped, torch.sign(u) * 1e4, torch.where(u_stopped, TINY, u / nD))
    J = torch.where(u >= 0, J_s * one_minus_wP, J_s)
    K_T_ahead = c.k0 + c.k1 * J + c.k2 * J * J
    K_T_reverse = torch.where(J_s >= c.C10, c.C6 + c.C7 * J_s, c.C3)
    K_T = torch.where(n > TINY, K_T_ahead, torch.where(n < -TINY, K_T_reverse, 0.0))
    return PropellerState(one_minus_wP, J_s, J, K_T, K_T_ahead)


def propeller_force(u, v, r, n, c, inflow: PropellerState | None = None):
    """X_P [N], Y_P [N], N_P [N m] for any quadrant.

    `c` provides rho, L_pp, d, D, P, t_P, A1..A8, B1..B8 and what `propeller_inflow` needs.
    """
    c = view_of(c, u)
    if inflow is None:
        inflow = propeller_inflow(u, v, r, n, c)
    J_s = inflow.J_s
    n2 = n * n
    ahead = n >= 0
    astern_motion = u < 0
    thrust_scale = c.rho * n2 * c.D4
    # n >= 0: K_T(J) with J = J_s for u < 0; n < 0: CMT reverse polynomial
    K_T_ahead = inflow.K_T_ahead
    if K_T_ahead is None:
        K_T_ahead = c.k0 + c.k1 * inflow.J + c.k2 * inflow.J * inflow.J
    X_P = torch.where(ahead, thrust_scale * c.one_minus_tP * K_T_ahead, thrust_scale * inflow.K_T)
    # lateral force and moment: Q2 polynomials in J_s times (n P)^2 (ahead revolutions,
    # astern motion, else 0); reverse rotation: piecewise linear in J_s times (n D)^2.
    # Y and N in one pass: (..., 2) lanes = (Y, N)
    Js = J_s[..., None]
    A = lambda *names: coefficient_vector(c, names, J_s)  # noqa: E731
    poly_Q2 = A("A6", "B6") * Js * Js + A("A7", "B7") * Js + A("A8", "B8")
    low, high = Js < -0.35, Js > -0.06
    reverse = torch.where(low, A("A3", "B3") + A("A4", "B4") * Js,
                          torch.where(high, A("A5", "B5"), A("A1", "B1") + A("A2", "B2") * Js))
    scale = coefficient_vector(c, ("q", "qL"), J_s)  # (q, q L)
    lateral = torch.where(ahead[..., None], torch.where(astern_motion[..., None], scale * (n2 * c.P2)[..., None] * poly_Q2, 0.0),
                          scale * (n2 * c.D2)[..., None] * reverse)
    return X_P, lateral[..., 0], lateral[..., 1]
