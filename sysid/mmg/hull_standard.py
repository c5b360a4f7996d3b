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

from sysid.mmg.coefficient_lookup import coefficient_matrix, view_of
from sysid.mmg.motion import Motion, motion_of_channels


# features (..., 16) times a (16, 3) coefficient matrix, with w = (v, rL) [m/s]:
# U^2, w x w (4, row-major), U w (2), (w x w) x w / U (8), v^4 / U^2
_Y = lambda name: (None, ("q", name), ("qL", name.replace("Y_", "N_")))  # noqa: E731
_ROWS = (((-1.0, "q", "R_0"), None, None),                                 # U^2
         (("q", "X_vv"), None, None), (("q", "X_vr"), None, None),          # v v, v rL
         (None, None, None), (("q", "X_rr"), None, None),                   # rL v, rL rL
         _Y("Y_v"), _Y("Y_r"),                                              # U v, U rL
         _Y("Y_vvv"), _Y("Y_vvr"), (None, None, None), _Y("Y_vrr"),         # v v v, v v rL, v rL v, v rL rL
         (None, None, None), (None, None, None), (None, None, None), _Y("Y_rrr"),  # rL v v .. rL rL rL
         (("q", "X_vvvv"), None, None))                                     # v^4 / U^2


def hull_forces_standard(m: Motion, c) -> torch.Tensor:
    """(X_H, Y_H, N_H) (..., 3) [N, N, N m] of a `Motion` (see `hull_force_standard`)."""
    k, U = m.k, m.U
    inverse_U = torch.where(m.slow, k.zero, m.U_guarded.reciprocal())  # 1/m/s, 0 below the guard
    w = torch.cat([m.v, m.r * c.L_pp], -1)
    w2 = (w[..., :, None] * w[..., None, :]).flatten(-2)
    w3 = (w2[..., :, None] * w[..., None, :]).flatten(-2) * inverse_U
    v2 = w2[..., :1]
    U2 = m.u * m.u + m.v * m.v if m.smooth else U * U  # m^2/s^2 (a finite gradient at rest)
    features = torch.cat([U2, w2, w * U, w3, v2 * v2 * (inverse_U * inverse_U)], -1)
    return features @ coefficient_matrix(c, _ROWS, U)


def hull_force_standard(u: torch.Tensor, v: torch.Tensor, r: torch.Tensor, c
                        ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """X_H [N], Y_H [N], N_H [N m about midship] from u, v (midship) [m/s], r [rad/s].

    `c` carries L_pp [m], d [m], rho [kg/m^3] and the derivatives of the family's table
    (`sysid.mmg.families`).
    Any batch shape; float32 or float64.
    """
    c = view_of(c, u)
    return hull_forces_standard(motion_of_channels(u, v, r, c), c).unbind(-1)
