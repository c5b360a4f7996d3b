"""Rudder forces of the standard MMG model (Yasukawa & Yoshimura 2015, Eqs. 17-27).

    X_R = -(1 - t_R) F_N sin(delta),  Y_R = -(1 + a_H) F_N cos(delta),
    N_R = -(x_R + a_H x_H) F_N cos(delta),  F_N = 1/2 rho A_R U_R^2 f_alpha sin(alpha_R),
    alpha_R = delta - atan2(v_R, u_R),  v_R = U gamma_R beta_R,  beta_R = beta - l_R r / U,
    u_R = epsilon u_P sqrt(eta {1 + kappa (sqrt(1 + 8 K_T / (pi J_P^2)) - 1)}^2 + 1 - eta),

with u_P = u (1 - w_P), eta = D / H_R and gamma_R = gamma_R_minus for beta_R < 0, else
gamma_R_plus. u_R is evaluated in the equivalent form without J_P in a denominator,
u_R = epsilon sqrt(eta {u_P + kappa (sqrt(u_P^2 + 8 K_T (n D)^2 / pi) - u_P)}^2 + (1 - eta) u_P^2),
identical for u_P > 0 and finite at J_P = 0. Positive delta turns the ship to starboard.
Unlike the paper, l_R here is in metres (l'_R L_pp), like the other lengths of the ship file.
"""
from __future__ import annotations

import torch

from sysid.mmg.coefficient_lookup import view_of
from sysid.mmg.guards import choose, safe_atan2, safe_sqrt
from sysid.mmg.motion import Motion, as_channels, as_lanes, motion_of_channels
from sysid.mmg.propeller import PropellerState
from sysid.mmg.rudder import RudderInflow, normal_force, rudder_lanes


def inflow_standard_of(m: Motion, c, prop: PropellerState) -> RudderInflow:
    """u_R, v_R [m/s], alpha_R [rad] of a `Motion` (F_N left to `rudder_lanes`)."""
    k, smooth = m.k, m.smooth
    u_P = m.u * prop.one_minus_wP
    u_P2 = u_P * u_P
    n2 = prop.n2 if prop.n2 is not None else m.n * m.n
    jet = torch.addcmul(u_P2, prop.K_T * n2, c.jet_D2)
    jet = safe_sqrt(jet) if smooth else torch.sqrt(torch.clamp(jet, min=0.0))
    core = torch.addcmul(u_P, c.kappa, jet - u_P)
    u_R = torch.addcmul(core * core * c.eps2_eta, c.eps2_one_minus_eta, u_P2)
    u_R = safe_sqrt(u_R) if smooth else torch.sqrt(torch.clamp(u_R, min=0.0))
    beta, r_nd = prop.beta, prop.r_nd
    if beta is None:
        beta = torch.where(m.slow, k.zero, -m.beta_hat)
        r_nd = torch.where(m.slow, k.zero, m.r * c.L_pp / m.U_guarded)
    beta_R = torch.addcmul(beta, c.minus_l_R_nd, r_nd)
    gamma_R = choose(beta_R < k.zero, c.gamma_R_minus, c.gamma_R_plus, beta_R)
    v_R = m.U * gamma_R * beta_R
    alpha_R = m.delta - (safe_atan2(v_R, u_R) if smooth else torch.atan2(v_R, u_R))
    return RudderInflow(u_R, v_R, alpha_R, None)


def rudder_forces_standard(m: Motion, c, prop: PropellerState) -> torch.Tensor:
    """(X_R, Y_R, N_R) (..., 3) [N, N, N m] of a `Motion` (see `rudder_force_standard`)."""
    return rudder_lanes(inflow_standard_of(m, c, prop), m.delta, c)


def rudder_inflow_standard(u, v, r, n, delta, c, prop: PropellerState) -> RudderInflow:
    """u_R, v_R [m/s], alpha_R [rad], F_N [N]; u, v [m/s], r [rad/s], n [rps], delta [rad]."""
    c = view_of(c, u)
    inflow = as_channels(inflow_standard_of(motion_of_channels(u, v, r, c, n, delta), c, as_lanes(prop)))
    return inflow._replace(F_N=normal_force(inflow, c))


def rudder_force_standard(u, v, r, n, delta, c, prop: PropellerState,
                          inflow: RudderInflow | None = None):
    """X_R [N], Y_R [N], N_R [N m about midship] from the rudder normal force."""
    c = view_of(c, u)
    if inflow is None:
        inflow = inflow_standard_of(motion_of_channels(u, v, r, c, n, delta), c, as_lanes(prop))
    else:
        inflow = as_lanes(inflow)
    return rudder_lanes(inflow, delta[..., None], c).unbind(-1)
