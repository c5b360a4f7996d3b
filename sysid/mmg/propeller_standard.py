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

from sysid.mmg.coefficient_lookup import coefficient_vector, view_of
from sysid.mmg.guards import choose
from sysid.mmg.motion import Motion, as_channels, as_lanes, motion_of_channels
from sysid.mmg.propeller import PropellerState


def wake_yasukawa(beta_P, c, k=None):
    """1 - w_P [-] with the C_1/C_2 correction of Yasukawa & Yoshimura (2015):
    (1 - w_P0) (1 + (1 - exp(-C_1 |beta_P|)) (C_2 - 1)), C_2 = C_2_plus for beta_P > 0."""
    if k is None:
        C_2 = choose(beta_P > 0, c.C_2_plus, c.C_2_minus, beta_P)
        return c.one_minus_wP0 * (1.0 + (1.0 - torch.exp(-c.C_1 * beta_P.abs())) * (C_2 - 1.0))
    rise = k.one - torch.exp(beta_P.abs() * c.minus_C_1)
    return torch.addcmul(c.one_minus_wP0, rise, choose(beta_P > k.zero, c.wake_plus, c.wake_minus, beta_P))


def wake_gaussian(beta_P, c, k=None):
    """1 - w_P [-] with w_P = w_P0 exp(-4 beta_P^2) (shipmmg's form)."""
    if k is None:
        return 1.0 - c.w_P0 * torch.exp(-4.0 * beta_P * beta_P)
    return torch.addcmul(k.one, c.minus_w_P0, torch.exp(beta_P * beta_P * k.minus_four))  # k: constants


def inflow_standard_of(m: Motion, c, wake=wake_yasukawa) -> PropellerState:
    """`propeller_inflow_standard` of a `Motion` (drift angle and r' kept for the rudder)."""
    k, u, n = m.k, m.u, m.n
    beta = torch.where(m.slow, k.zero, -m.beta_hat)
    r_nd = torch.where(m.slow, k.zero, m.r * c.L_pp / m.U_guarded)
    one_minus_wP = wake(torch.addcmul(beta, c.minus_x_P, r_nd), c, k)
    turning = n.abs() >= k.tiny
    nD = n * c.D
    J_s = torch.where(turning, u / (torch.where(turning, nD, k.one) if m.smooth else nD), k.zero)
    J = J_s * one_minus_wP
    K_T = torch.addcmul(c.k0, torch.addcmul(c.k1, c.k2, J), J)
    return PropellerState(one_minus_wP, J_s, J, K_T, n2=n * n, beta=beta, r_nd=r_nd)


def propeller_inflow_standard(u, v, r, n, c, wake=wake_yasukawa) -> PropellerState:
    """Wake, advance ratio and K_T; u, v [m/s], r [rad/s], n [rps].

    Returns the `PropellerState` every rudder model reads (J_s = u / (n D) [-]).
    """
    c = view_of(c, u)
    return as_channels(inflow_standard_of(motion_of_channels(u, v, r, c, n), c, wake))


def propeller_forces_standard(m: Motion, c, inflow: PropellerState) -> torch.Tensor:
    """(X_P, 0, 0) (..., 3) [N, N, N m] of a `Motion` (see `propeller_force_standard`)."""
    n2 = inflow.n2 if inflow.n2 is not None else m.n * m.n
    X_P = inflow.K_T * n2 * c.one_minus_tP_rho_D4
    return X_P * coefficient_vector(c, (1.0, None, None), X_P)


def propeller_force_standard(u, v, r, n, c, inflow: PropellerState | None = None,
                             wake=wake_yasukawa):
    """X_P [N], Y_P = 0 [N], N_P = 0 [N m]; `c` provides rho, D, t_P and the inflow terms."""
    c = view_of(c, u)
    m = motion_of_channels(u, v, r, c, n)
    inflow = inflow_standard_of(m, c, wake) if inflow is None else as_lanes(inflow)
    return propeller_forces_standard(m, c, inflow).unbind(-1)
