"""Hull forces of the standard MMG model (Yasukawa & Yoshimura 2015, J. Mar. Sci. Technol.
20:37-52, Eqs. 7-9): polynomials in the drift and yaw-rate ratios.

    X_H = 1/2 rho L d U^2 (-R'_0 + X'vv v'^2 + X'vr v' r' + X'rr r'^2 + X'vvvv v'^4)
    Y_H = 1/2 rho L d U^2 (Y'v v' + Y'r r' + Y'vvv v'^3 + Y'vvr v'^2 r' + Y'vrr v' r'^2 + Y'rrr r'^3)
    N_H = 1/2 rho L^2 d U^2 (N'v v' + N'r r' + N'vvv v'^3 + N'vvr v'^2 r' + N'vrr v' r'^2 + N'rrr r'^3)

with U = sqrt(u^2 + v_m^2), v' = v_m / U, r' = r L / U (v_m at midship, positive to
starboard). The model is meant for ahead motion (u > 0). It is evaluated in the expanded
form U^2 v'^i r'^j = v^i (rL)^j / U^(i+j-2): no division for the linear terms, and the
higher-order terms vanish smoothly as U -> 0.
"""
from __future__ import annotations

import torch

from sysid.mmg.coefficients import view_of
from sysid.mmg.guards import SPEED_GUARD, safe_div


def hull_force_standard(u: torch.Tensor, v: torch.Tensor, r: torch.Tensor, c
                        ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """X_H [N], Y_H [N], N_H [N m about midship] from u, v (midship) [m/s], r [rad/s].

    `c` carries L_pp [m], d [m], rho [kg/m^3] and the derivatives of the family's table
    (`sysid.mmg.families`).
    Any batch shape; float32 or float64.
    """
    c = view_of(c, u)
    L = c.L_pp
    q = c.q  # kg/m, 1/2 rho L d
    U2 = u * u + v * v
    U = torch.sqrt(U2)
    moving = U >= SPEED_GUARD
    rL = r * L  # m/s
    # U^2 * monomials of (v', r'): degree 2 -> no U, degree 3 -> /U, degree 4 -> /U^2
    X_nd = (-c.R_0 * U2 + c.X_vv * v * v + c.X_vr * v * rL + c.X_rr * rL * rL
            + c.X_vvvv * safe_div(v ** 4, U2, moving))
    cubic_Y = c.Y_vvv * v ** 3 + c.Y_vvr * v * v * rL + c.Y_vrr * v * rL * rL + c.Y_rrr * rL ** 3
    cubic_N = c.N_vvv * v ** 3 + c.N_vvr * v * v * rL + c.N_vrr * v * rL * rL + c.N_rrr * rL ** 3
    Y_nd = (c.Y_v * v + c.Y_r * rL) * U + safe_div(cubic_Y, U, moving)
    N_nd = (c.N_v * v + c.N_r * rL) * U + safe_div(cubic_N, U, moving)
    return q * X_nd, q * Y_nd, c.qL * N_nd
