"""Rudder forces (paper Eqs. 36-48; docs: MMG equations).

Longitudinal rudder inflow u_R has three branches: Yoshimura's low-speed form when
n >= 0 and K_T > 0; Kitagawa's reverse-rotation form otherwise when u >= 0; and u_R = u
otherwise (astern motion). Only the normal force F_N acts.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import torch

from sysid.mmg.guards import safe_atan2, safe_sqrt
from sysid.mmg.propeller import PropellerState


class RudderInflow(NamedTuple):
    u_R: torch.Tensor      # m/s, longitudinal inflow
    v_R: torch.Tensor      # m/s, lateral inflow
    alpha_R: torch.Tensor  # rad, effective inflow angle
    F_N: torch.Tensor      # N, rudder normal force


def rudder_inflow(u, v, r, n, delta, c, prop: PropellerState) -> RudderInflow:
    """Inflow velocities, angle and normal force at the rudder.

    u, v [m/s], r [rad/s], n [rps], delta [rad, positive to starboard]; `c` provides
    rho, D, A_R, lambda_R, epsilon, k_x, k_xPR, C_PR, x_R, l_R, gamma_P, gamma_N.
    """
    H_R = torch.sqrt(c.A_R * c.lambda_R)
    eta = c.D / H_R
    kappa = c.k_x / c.epsilon
    K_T = prop.K_T
    u_p = u * prop.one_minus_wP
    # Yoshimura: n >= 0 and K_T > 0
    jet = safe_sqrt(u_p * u_p + 8.0 * K_T * n * n * c.D**2 / math.pi)
    core = u_p + kappa * (jet - u_p)
    u_R_yoshimura = c.epsilon * safe_sqrt(eta * core * core + (1.0 - eta) * u_p * u_p)
    # Kitagawa: otherwise, u >= 0
    u2 = u * c.epsilon * prop.one_minus_wP
    u1 = u2 + n * c.D * c.k_xPR * safe_sqrt(8.0 * K_T.abs() / math.pi)
    s = eta * torch.sign(u1) * u1 * u1 + (1.0 - eta) * u2 * u2 + c.C_PR * u * u
    u_R_kitagawa = torch.sign(s) * safe_sqrt(s.abs())
    u_R = torch.where((n >= 0) & (K_T > 0), u_R_yoshimura, torch.where(u >= 0, u_R_kitagawa, u))

    gamma = torch.where(v + c.x_R * r >= 0, c.gamma_P + 0.0 * v, c.gamma_N + 0.0 * v)
    v_R = -gamma * (v + c.l_R * r)
    alpha_R = delta - safe_atan2(v_R, u_R)
    f_alpha = 6.13 * c.lambda_R / (2.25 + c.lambda_R)  # Fujii's normal-force gradient
    F_N = 0.5 * c.rho * c.A_R * (u_R * u_R + v_R * v_R) * f_alpha * torch.sin(alpha_R)
    return RudderInflow(u_R, v_R, alpha_R, F_N)


def rudder_force(u, v, r, n, delta, c, prop: PropellerState, inflow: RudderInflow | None = None):
    """X_R [N], Y_R [N], N_R [N m] from the rudder normal force (paper Eqs. 36-38)."""
    if inflow is None:
        inflow = rudder_inflow(u, v, r, n, delta, c, prop)
    F_N = inflow.F_N
    cos_d, sin_d = torch.cos(delta), torch.sin(delta)
    X_R = -(1.0 - c.t_R) * F_N * sin_d
    Y_R = -(1.0 + c.a_H) * F_N * cos_d
    N_R = -(c.x_R + c.a_H * c.x_H) * F_N * cos_d
    return X_R, Y_R, N_R
