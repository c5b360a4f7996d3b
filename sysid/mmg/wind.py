"""Wind forces: Fujiwara's regression (paper Eqs. 49-54; docs: MMG equations).

The input is the *true* wind (U_T, zeta: speed and the earth-frame direction it comes
from, x0 towards y0); the relative wind is computed from the ship's current state, as the
lab's simulator does in every right-hand-side call.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import torch

from sysid.mmg.coefficients import coefficient_matrix, coefficient_vector, view_of
from sysid.mmg.guards import SPEED_GUARD, safe_atan2

TWO_PI = 2.0 * math.pi


class RelativeWind(NamedTuple):
    U_A: torch.Tensor      # m/s, relative wind speed at midship
    gamma_A: torch.Tensor  # rad in [0, 2 pi), direction it comes from, bow towards starboard


def relative_wind(u, v, psi, U_T, zeta) -> RelativeWind:
    """True wind to relative wind at midship, with the simulator's low-speed guards.

    u, v [m/s] midship body velocity, psi [rad] heading, U_T [m/s], zeta [rad].
    """
    U = torch.hypot(u, v)
    slow = U < SPEED_GUARD
    beta_hat = safe_atan2(v, u)
    course = psi + beta_hat
    U_guarded = torch.where(slow, 1e-7, U)
    # 'from' vector of the relative wind = true 'from' vector + ship velocity (earth frame)
    W_x = U_T * torch.cos(zeta) + U_guarded * torch.cos(course)
    W_y = U_T * torch.sin(zeta) + U_guarded * torch.sin(course)
    U_A = torch.sqrt(W_x * W_x + W_y * W_y)
    # the angle before reduction to [0, 2 pi): from the relative 'from' vector; below the
    # speed guard the true wind's; without true wind (wins) the drift angle's
    angle = torch.where(slow, zeta, safe_atan2(W_y, W_x)) - psi
    angle = torch.where(U_T < SPEED_GUARD, beta_hat, angle)
    gamma_A = torch.remainder(angle, TWO_PI)
    return RelativeWind(U_A, gamma_A)


# Fujiwara's coefficients by harmonic: rows cos(k aoa) for k = 1, 3, 5 (C_X) and sin(k aoa)
# for k = 1, 3, 5, 2 (C_Y, C_N); columns (C_X, C_Y, C_N)
_HARMONICS = (1.0, 3.0, 5.0, 2.0)
_FUJIWARA = (("X1", None, None), ("X3", None, None), ("X5", None, None), (None, None, None),
             (None, "Y1", "N1"), (None, "Y3", "N3"), (None, "Y5", None), (None, None, "N2"))


def wind_force(U_A, gamma_A, c):
    """X_A [N], Y_A [N], N_A [N m] from the relative wind (U_A [m/s], gamma_A [rad]).

    `c` provides rho_air, A_T, A_L, L_wind and Fujiwara's X0..X5, Y1..Y5, N1..N3.
    C_X = X0 + sum_k X_k cos(k aoa), C_Y = sum_k Y_k sin(k aoa), C_N = sum_k N_k sin(k aoa),
    aoa = 2 pi - gamma_A, evaluated as one (..., 8) x (8, 3) product.
    """
    c = view_of(c, U_A)
    aoa = (TWO_PI - gamma_A)[..., None] * coefficient_vector(c, _HARMONICS, U_A)  # (..., 4)
    harmonics = torch.cat([torch.cos(aoa), torch.sin(aoa)], -1)                    # (..., 8)
    C = torch.addmm(coefficient_vector(c, ("X0", None, None), U_A), harmonics.reshape(-1, 8),
                    coefficient_matrix(c, _FUJIWARA, U_A)).view(U_A.shape + (3,))
    dyn = c.half_rho_air * U_A * U_A  # Pa
    F = dyn[..., None] * coefficient_vector(c, ("A_T", "A_L", ("A_L", "L_wind")), U_A) * C
    return F.unbind(-1)
