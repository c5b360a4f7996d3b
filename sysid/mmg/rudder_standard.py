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

import math

import torch

from sysid.mmg.coefficients import view_of
from sysid.mmg.guards import choose, safe_atan2, safe_sqrt
from sysid.mmg.propeller import PropellerState
from sysid.mmg.propeller_standard import drift_angles
from sysid.mmg.rudder import RudderInflow, rudder_components


def rudder_inflow_standard(u, v, r, n, delta, c, prop: PropellerState) -> RudderInflow:
    """u_R, v_R [m/s], alpha_R [rad], F_N [N]; u, v [m/s], r [rad/s], n [rps], delta [rad]."""
    c = view_of(c, u)
    eta = c.eta  # D / H_R
    u_P = u * prop.one_minus_wP
    jet = safe_sqrt(u_P * u_P + 8.0 * prop.K_T * n * n * c.D2 / math.pi)
    core = u_P + c.kappa * (jet - u_P)
    u_R = c.epsilon * safe_sqrt(eta * core * core + c.one_minus_eta * u_P * u_P)
    beta, r_nd = drift_angles(u, v, r, c.L_pp)
    beta_R = beta - c.l_R_nd * r_nd
    gamma_R = choose(beta_R < 0, c.gamma_R_minus, c.gamma_R_plus, beta_R)
    U = torch.hypot(u, v)
    v_R = U * gamma_R * beta_R
    alpha_R = delta - safe_atan2(v_R, u_R)
    F_N = c.half_rho_A_R * (u_R * u_R + v_R * v_R) * c.f_alpha * torch.sin(alpha_R)
    return RudderInflow(u_R, v_R, alpha_R, F_N)


def rudder_force_standard(u, v, r, n, delta, c, prop: PropellerState,
                          inflow: RudderInflow | None = None):
    """X_R [N], Y_R [N], N_R [N m about midship] from the rudder normal force."""
    c = view_of(c, u)
    if inflow is None:
        inflow = rudder_inflow_standard(u, v, r, n, delta, c, prop)
    return rudder_components(inflow.F_N, delta, c)
