"""Rudder forces (paper Eqs. 36-48; docs: MMG equations).

Longitudinal rudder inflow u_R has three branches: Yoshimura's low-speed form when
n >= 0 and K_T > 0; Kitagawa's reverse-rotation form otherwise when u >= 0; and u_R = u
otherwise (astern motion). Only the normal force F_N acts.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import torch

from sysid.mmg.coefficients import view_of
from sysid.mmg.guards import choose, safe_atan2, safe_sqrt
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
    c = view_of(c, u)
    eta = c.eta  # D / H_R, H_R = sqrt(A_R lambda_R)
    kappa = c.kappa  # k_x / epsilon
    K_T = prop.K_T
    u_p = u * prop.one_minus_wP
    # Yoshimura: n >= 0 and K_T > 0
    u_p2 = u_p * u_p
    jet = safe_sqrt(u_p2 + 8.0 * K_T * n * n * c.D2 / math.pi)
    core = u_p + kappa * (jet - u_p)
    u_R_yoshimura = c.epsilon * safe_sqrt(eta * core * core + c.one_minus_eta * u_p2)
    # Kitagawa: otherwise, u >= 0
    u2 = u * c.epsilon * prop.one_minus_wP
    u1 = u2 + n * c.D * c.k_xPR * safe_sqrt(8.0 * K_T.abs() / math.pi)
    s = eta * torch.sign(u1) * u1 * u1 + c.one_minus_eta * u2 * u2 + c.C_PR * u * u
    u_R_kitagawa = torch.sign(s) * safe_sqrt(s.abs())
    u_R = torch.where((n >= 0) & (K_T > 0), u_R_yoshimura, torch.where(u >= 0, u_R_kitagawa, u))

    gamma = choose(v + c.x_R * r >= 0, c.gamma_P, c.gamma_N, v)
    v_R = -gamma * (v + c.l_R * r)
    alpha_R = delta - safe_atan2(v_R, u_R)
    F_N = c.half_rho_A_R * (u_R * u_R + v_R * v_R) * c.f_alpha * torch.sin(alpha_R)
    return RudderInflow(u_R, v_R, alpha_R, F_N)


def rudder_force(u, v, r, n, delta, c, prop: PropellerState, inflow: RudderInflow | None = None):
    """X_R [N], Y_R [N], N_R [N m] from the rudder normal force (paper Eqs. 36-38)."""
    c = view_of(c, u)
    if inflow is None:
        inflow = rudder_inflow(u, v, r, n, delta, c, prop)
    return rudder_components(inflow.F_N, delta, c)


def rudder_components(F_N, delta, c):
    """X_R = -(1 - t_R) F_N sin(delta), Y_R = -(1 + a_H) F_N cos(delta),
    N_R = -(x_R + a_H x_H) F_N cos(delta) [N, N, N m], from F_N [N] and delta [rad]."""
    cos_d = torch.cos(delta)
    return c.minus_one_minus_tR * F_N * torch.sin(delta), c.minus_one_plus_aH * F_N * cos_d, c.minus_N_R_lever * F_N * cos_d
