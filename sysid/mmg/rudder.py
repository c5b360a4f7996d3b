"""Rudder forces (paper Eqs. 36-48; docs: MMG equations).

Longitudinal rudder inflow u_R has three branches: Yoshimura's low-speed form when
n >= 0 and K_T > 0; Kitagawa's reverse-rotation form otherwise when u >= 0; and u_R = u
otherwise (astern motion). Only the normal force F_N acts.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import torch

from sysid.mmg.coefficient_lookup import coefficient_vectors, view_of
from sysid.mmg.guards import choose, safe_atan2, safe_sqrt
from sysid.mmg.motion import Motion, as_channels, as_lanes, motion_of_channels
from sysid.mmg.propeller import PropellerState


class RudderInflow(NamedTuple):
    u_R: torch.Tensor      # m/s, longitudinal inflow
    v_R: torch.Tensor      # m/s, lateral inflow
    alpha_R: torch.Tensor  # rad, effective inflow angle
    F_N: torch.Tensor      # N, rudder normal force (None from `inflow_of`: see `rudder_lanes`)


def _sqrt(x: torch.Tensor, smooth: bool) -> torch.Tensor:
    """sqrt(max(x, 0)), with a finite gradient at 0 where `smooth`."""
    return safe_sqrt(x) if smooth else torch.sqrt(torch.clamp(x, min=0.0))


def inflow_of(m: Motion, c, prop: PropellerState) -> RudderInflow:
    """u_R, v_R [m/s], alpha_R [rad] of a `Motion` (F_N left to `rudder_lanes`)."""
    k, u, n, smooth = m.k, m.u, m.n, m.smooth
    K_T = prop.K_T
    n2 = prop.n2 if prop.n2 is not None else n * n
    u_p = u * prop.one_minus_wP
    u_p2 = u_p * u_p
    # Yoshimura (n >= 0 and K_T > 0): u_R^2 = epsilon^2 (eta core^2 + (1 - eta) u_p^2),
    # core = u_p + kappa (sqrt(u_p^2 + 8 K_T (n D)^2 / pi) - u_p)
    jet = torch.addcmul(u_p2, K_T * n2, c.jet_D2)
    jet = safe_sqrt(jet) if smooth else torch.sqrt(jet)  # >= 0 where this branch is taken
    core = torch.addcmul(u_p, c.kappa, jet - u_p)
    outer = u_p2 * c.eps2_one_minus_eta  # (1 - eta) (epsilon u_p)^2 [m^2/s^2], in both forms
    u_R_yoshimura = _sqrt(torch.addcmul(outer, core * core, c.eps2_eta), smooth)
    # Kitagawa (otherwise, u >= 0): u1 = epsilon u_p + n D k_xPR sqrt(8 |K_T| / pi)
    # (= epsilon u1' below), s = eta u1 |u1| + (1 - eta) (epsilon u_p)^2 + C_PR u^2,
    # u_R = sign(s) sqrt(|s|)
    race = K_T.abs() * c.kitagawa_jet_eps2  # (n D k_xPR / epsilon)^2 8 |K_T| / pi / n^2
    u1 = torch.addcmul(u_p, n, safe_sqrt(race) if smooth else torch.sqrt(race))
    s = torch.addcmul(torch.addcmul(outer, u1 * u1.abs(), c.eps2_eta), c.C_PR, u * u)
    if smooth:
        u_R_kitagawa = torch.sign(s) * safe_sqrt(s.abs())
    else:
        u_R_kitagawa = torch.copysign(torch.sqrt(s.abs()), s)
    ahead = prop.turning_ahead if prop.turning_ahead is not None else n >= k.zero
    moving_ahead = prop.moving_ahead if prop.moving_ahead is not None else u >= k.zero
    u_R = torch.where(ahead & (K_T > k.zero), u_R_yoshimura, torch.where(moving_ahead, u_R_kitagawa, u))

    straightening = choose(torch.addcmul(m.v, c.x_R, m.r) >= k.zero, c.minus_gamma_P, c.minus_gamma_N, m.v)
    v_R = straightening * torch.addcmul(m.v, c.l_R, m.r)
    alpha_R = m.delta - (safe_atan2(v_R, u_R) if smooth else torch.atan2(v_R, u_R))
    return RudderInflow(u_R, v_R, alpha_R, None)


_SIN_COS_COS = (None, 0.5 * math.pi, 0.5 * math.pi)  # phases: sin(x + pi/2) = cos(x)
# X_R = -(1 - t_R) F_N sin(delta), Y_R = -(1 + a_H) F_N cos(delta),
# N_R = -(x_R + a_H x_H) F_N cos(delta), F_N = 1/2 rho A_R f_alpha U_R^2 sin(alpha_R)
_LANES = (("minus_one_minus_tR", "half_rho_A_R", "f_alpha"), ("minus_one_plus_aH", "half_rho_A_R", "f_alpha"),
          ("minus_N_R_lever", "half_rho_A_R", "f_alpha"))
_RUDDER = (_SIN_COS_COS, _LANES)


def rudder_lanes(inflow: RudderInflow, delta: torch.Tensor, c) -> torch.Tensor:
    """(X_R [N], Y_R [N], N_R [N m]) (..., 3) from u_R, v_R [m/s], alpha_R and delta [rad],
    each (..., 1) (paper Eqs. 36-38); `c` provides rho, A_R, f_alpha, t_R, a_H, x_R, x_H."""
    u_R, v_R = inflow.u_R, inflow.v_R
    F_N = torch.addcmul(u_R * u_R, v_R, v_R) * torch.sin(inflow.alpha_R)  # / (1/2 rho A_R f_alpha)
    # (sin, cos, cos)(delta) as sin(delta + (0, pi/2, pi/2))
    phases, scale = coefficient_vectors(c, _RUDDER, delta)
    return torch.sin(delta + phases) * scale * F_N


def rudder_forces(m: Motion, c, prop: PropellerState) -> torch.Tensor:
    """(X_R, Y_R, N_R) (..., 3) [N, N, N m] of a `Motion` (see `rudder_force`)."""
    return rudder_lanes(inflow_of(m, c, prop), m.delta, c)


def rudder_inflow(u, v, r, n, delta, c, prop: PropellerState) -> RudderInflow:
    """Inflow velocities, angle and normal force at the rudder.

    u, v [m/s], r [rad/s], n [rps], delta [rad, positive to starboard]; `c` provides
    rho, D, A_R, lambda_R, epsilon, k_x, k_xPR, C_PR, x_R, l_R, gamma_P, gamma_N.
    Longitudinal inflow: Yoshimura's form where n >= 0 and K_T > 0, else Kitagawa's where
    u >= 0, else u.
    """
    c = view_of(c, u)
    inflow = as_channels(inflow_of(motion_of_channels(u, v, r, c, n, delta), c, as_lanes(prop)))
    return inflow._replace(F_N=normal_force(inflow, c))


def normal_force(inflow: RudderInflow, c) -> torch.Tensor:
    """F_N [N] = 1/2 rho A_R f_alpha (u_R^2 + v_R^2) sin(alpha_R)."""
    return c.half_rho_A_R * (inflow.u_R * inflow.u_R + inflow.v_R * inflow.v_R) * c.f_alpha * torch.sin(inflow.alpha_R)


def rudder_force(u, v, r, n, delta, c, prop: PropellerState, inflow: RudderInflow | None = None):
    """X_R [N], Y_R [N], N_R [N m] from the rudder normal force (paper Eqs. 36-38)."""
    c = view_of(c, u)
    if inflow is None:
        inflow = inflow_of(motion_of_channels(u, v, r, c, n, delta), c, as_lanes(prop))
    else:
        inflow = as_lanes(inflow)
    return rudder_lanes(inflow, delta[..., None], c).unbind(-1)
