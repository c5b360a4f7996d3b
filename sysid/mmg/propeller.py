"""Propeller forces in four quadrants (paper Eqs. 27-35; docs: MMG equations).

Q1: n >= 0, u >= 0 (standard MMG thrust); Q2: n >= 0, u < 0 (thrust plus lateral
polynomials in J_s); Q3/Q4: n < 0 (CMT reverse-rotation polynomials). n = 0 follows the
n >= 0 formulas, which give zero force.
"""
from __future__ import annotations

from typing import NamedTuple

import torch

from sysid.mmg.coefficient_lookup import coefficient_vectors, view_of
from sysid.mmg.motion import Motion, as_channels, as_lanes, motion_of_channels


class PropellerState(NamedTuple):
    """Intermediate propeller quantities, also needed by the rudder model."""

    one_minus_wP: torch.Tensor  # -, 1 - w_P, clipped to (0, 1]
    J_s: torch.Tensor           # -, u / (n D) (guarded)
    J: torch.Tensor             # -, advance ratio with wake for u >= 0
    K_T: torch.Tensor           # -, thrust coefficient the rudder sees (0 for n = 0)
    K_T_ahead: torch.Tensor | None = None  # -, K_T(J) of ahead revolutions, where computed
    n2: torch.Tensor | None = None         # rps^2, n^2, where computed
    turning_ahead: torch.Tensor | None = None  # n >= 0, where computed
    moving_ahead: torch.Tensor | None = None   # u >= 0, where computed
    beta: torch.Tensor | None = None       # rad, drift angle atan2(-v, u) (0 below the speed guard), where computed
    r_nd: torch.Tensor | None = None       # -, r' = r L / U (0 below the speed guard), where computed


def inflow_of(m: Motion, c) -> PropellerState:
    """`propeller_inflow` of a `Motion` (fields (..., 1))."""
    k, u, n = m.k, m.u, m.n
    # lateral inflow at the propeller s = v' + x'_P r' (v' = v / U, r' = r L / U); below
    # the speed guard v' = r' = 1e-7
    s = torch.where(m.slow, c.slow_lateral_inflow, torch.addcmul(m.v, c.x_P_L, m.r) / m.U_guarded)
    # 1 - w_P = 1 - w_P0 + |s| (tau + C_P |s|), for u > 0 only, within [TINY, 1]
    s_abs = s.abs()
    one_minus_wP = torch.addcmul(c.one_minus_wP0, torch.addcmul(c.tau, c.C_P, s_abs), s_abs)
    one_minus_wP = torch.where(u > k.zero, one_minus_wP.clamp(k.tiny, k.one), k.one)

    n_stopped = n.abs() < k.tiny
    u_stopped = u.abs() < k.tiny
    nD = (torch.where(n_stopped, k.one, n) if m.smooth else n) * c.D
    J_s = torch.where(n_stopped, torch.sign(u) * k.stopped_ratio, torch.where(u_stopped, k.tiny, u / nD))
    moving_ahead = u >= k.zero
    J = torch.where(moving_ahead, J_s * one_minus_wP, J_s)
    K_T_ahead = torch.addcmul(c.k0, torch.addcmul(c.k1, c.k2, J), J)
    K_T_reverse = torch.where(J_s >= c.C10, torch.addcmul(c.C6, c.C7, J_s), c.C3)
    turning_ahead = n >= k.zero
    # 0 for |n| < TINY, K_T(J) ahead, the CMT line in reverse rotation
    K_T = torch.where(n_stopped, k.zero, torch.where(turning_ahead, K_T_ahead, K_T_reverse))
    return PropellerState(one_minus_wP, J_s, J, K_T, K_T_ahead, n * n, turning_ahead, moving_ahead)


def propeller_inflow(u, v, r, n, c) -> PropellerState:
    """Wake fraction, advance ratios and thrust coefficient.

    u, v [m/s], r [rad/s], n [rps]; `c` provides L_pp, D, w_P0, tau, C_P, x_P, k0..k2,
    C3, C6, C7, C10.
    """
    c = view_of(c, u)
    return as_channels(inflow_of(motion_of_channels(u, v, r, c, n), c))


# the lateral force and moment lanes (Y, N) [N, N m]: (q, q L) times (n P)^2 times the
# second-quadrant polynomial in J_s, or (n D)^2 times the reverse-rotation piecewise lines
_Q2 = tuple((("q", "P2", f"A{i}"), ("qL", "P2", f"B{i}")) for i in (6, 7, 8))
_REVERSE = tuple((("q", "D2", f"A{i}"), ("qL", "D2", f"B{i}")) for i in range(1, 6))
_LATERAL = _Q2 + _REVERSE + ((-0.35,), (-0.06,))  # J_s bounds of the reverse-rotation lines


def propeller_forces(m: Motion, c, inflow: PropellerState) -> torch.Tensor:
    """(X_P [N], Y_P [N], N_P [N m]) (..., 3) of a `Motion` (see `propeller_force`)."""
    k = m.k
    n2 = inflow.n2 if inflow.n2 is not None else m.n * m.n
    ahead = inflow.turning_ahead if inflow.turning_ahead is not None else m.n >= k.zero
    moving_ahead = inflow.moving_ahead if inflow.moving_ahead is not None else m.u >= k.zero
    K_T_ahead = inflow.K_T_ahead
    if K_T_ahead is None:
        K_T_ahead = torch.addcmul(c.k0, torch.addcmul(c.k1, c.k2, inflow.J), inflow.J)
    # n >= 0: (1 - t_P) rho D^4 K_T(J), J = J_s for u < 0; n < 0: rho D^4 K_T (CMT reverse)
    X_P = torch.where(ahead, K_T_ahead * c.one_minus_tP_rho_D4, inflow.K_T * c.rho_D4)
    Js = inflow.J_s
    A6, A7, A8, A1, A2, A3, A4, A5, low, high = coefficient_vectors(c, _LATERAL, Js)
    second = torch.addcmul(A8, torch.addcmul(A7, A6, Js), Js)
    reverse = torch.where(Js < low, torch.addcmul(A3, A4, Js),
                          torch.where(Js > high, A5, torch.addcmul(A1, A2, Js)))
    lateral = torch.where(ahead, torch.where(moving_ahead, k.zero, second), reverse)
    return torch.cat([X_P, lateral], -1) * n2


def propeller_force(u, v, r, n, c, inflow: PropellerState | None = None):
    """X_P [N], Y_P [N], N_P [N m] for any quadrant.

    `c` provides rho, L_pp, d, D, P, t_P, A1..A8, B1..B8 and what `propeller_inflow` needs.
    Y_P, N_P: Q2 polynomials in J_s times (n P)^2 (ahead revolutions, astern motion, else
    0); reverse rotation: piecewise linear in J_s times (n D)^2.
    """
    c = view_of(c, u)
    m = motion_of_channels(u, v, r, c, n)
    return propeller_forces(m, c, as_lanes(inflow) if inflow is not None else inflow_of(m, c)).unbind(-1)
