"""Propeller thrust of the standard MMG model (Yasukawa & Yoshimura 2015).

    X_P = (1 - t_P) rho n^2 D^4 K_T(J_P),   K_T = k0 + k1 J_P + k2 J_P^2,
    J_P = u (1 - w_P) / (n D),               Y_P = N_P = 0,

with the wake fraction in maneuvering motion depending on the geometric inflow angle at
the propeller, beta_P = beta - x'_P r' (beta = atan2(-v_m, u), r' = r L / U):

* ``standard`` (the paper's wake correction):
  1 - w_P = (1 - w_P0) [1 + (1 - exp(-C_1 |beta_P|)) (C_2 - 1)],
  C_2 = C_2_plus for beta_P > 0, C_2_minus otherwise;
* ``standard_gaussian_wake``: w_P = w_P0 exp(-4 beta_P^2), the form the shipmmg package
  (0.0.11) implements instead.

The paper is not on this machine: the formulas are written as the paper's from the
authors' reading of it (equation numbers are not given for that reason); shipmmg's form
is checked against shipmmg itself (tests/mmg/test_shipmmg_kvlcc2.py).

Ahead motion and ahead revolutions (u > 0, n > 0) are the model's range; n = 0 gives zero
thrust and J_P = 0.
"""
from __future__ import annotations

import torch

from sysid.mmg.coefficients import view_of
from sysid.mmg.guards import SPEED_GUARD, TINY, choose, safe_atan2, safe_div
from sysid.mmg.propeller import PropellerState


def drift_angles(u, v, r, L):
    """beta = atan2(-v_m, u) [rad] (positive: flow from port ahead) and r' = r L / U [-];
    both 0 below the speed guard."""
    U = torch.hypot(u, v)
    moving = U >= SPEED_GUARD
    beta = torch.where(moving, safe_atan2(-v, u), 0.0)
    r_nd = safe_div(r * L, U, moving)
    return beta, r_nd


def wake_yasukawa(beta_P, c):
    """1 - w_P [-] with the C_1/C_2 correction of Yasukawa & Yoshimura (2015)."""
    C_2 = choose(beta_P > 0, c.C_2_plus, c.C_2_minus, beta_P)
    return c.one_minus_wP0 * (1.0 + (1.0 - torch.exp(-c.C_1 * beta_P.abs())) * (C_2 - 1.0))


def wake_gaussian(beta_P, c):
    """1 - w_P [-] with w_P = w_P0 exp(-4 beta_P^2) (shipmmg's form)."""
    return 1.0 - c.w_P0 * torch.exp(-4.0 * beta_P * beta_P)


def propeller_inflow_standard(u, v, r, n, c, wake=wake_yasukawa) -> PropellerState:
    """Wake, advance ratio and K_T; u, v [m/s], r [rad/s], n [rps].

    Returns the `PropellerState` every rudder model reads (J_s = u / (n D) [-]).
    """
    c = view_of(c, u)
    beta, r_nd = drift_angles(u, v, r, c.L_pp)
    one_minus_wP = wake(beta - c.x_P * r_nd, c)
    turning = n.abs() >= TINY
    nD = n * c.D
    J_s = safe_div(u, nD, turning)
    J = J_s * one_minus_wP
    K_T = c.k0 + c.k1 * J + c.k2 * J * J
    return PropellerState(one_minus_wP, J_s, J, K_T)


def propeller_force_standard(u, v, r, n, c, inflow: PropellerState | None = None,
                             wake=wake_yasukawa):
    """X_P [N], Y_P = 0 [N], N_P = 0 [N m]; `c` provides rho, D, t_P and the inflow terms."""
    c = view_of(c, u)
    if inflow is None:
        inflow = propeller_inflow_standard(u, v, r, n, c, wake)
    X_P = c.one_minus_tP_rho * n * n * c.D4 * inflow.K_T
    zero = torch.zeros_like(X_P)
    return X_P, zero, zero
