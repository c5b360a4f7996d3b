"""Wind forces: Fujiwara's regression (paper Eqs. 49-54; docs: MMG equations).

The input is the *true* wind (U_T, zeta: speed and the earth-frame direction it comes
from, x0 towards y0); the relative wind is computed from the ship's current state, as the
lab's simulator does in every right-hand-side call.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import torch

from sysid.mmg.coefficient_lookup import Rows, coefficient_vectors, view_of
from sysid.mmg.guards import safe_atan2
from sysid.mmg.motion import _TWO, Motion, as_channels, motion_of_channels

TWO_PI = 2.0 * math.pi


class RelativeWind(NamedTuple):
    U_A: torch.Tensor      # m/s, relative wind speed at midship
    gamma_A: torch.Tensor  # rad in [0, 2 pi), direction it comes from, bow towards starboard


_HALF_PI = 0.5 * math.pi


def relative_wind_of(m: Motion) -> RelativeWind:
    """`relative_wind` of a `Motion` (with psi, U_T and zeta), fields (..., 1)."""
    k = m.k
    course = m.psi + m.beta_hat
    # 'from' vector of the relative wind = true 'from' vector + ship velocity (earth frame)
    if m.smooth:  # real arithmetic (gradients, compiled code): rows (zeta, course) x (cos, sin)
        angles = torch.cat([m.zeta, course], -1)[..., None]
        trig = torch.sin(angles + k.cos_sin_phase)  # the cosines as sin(x + pi/2)
        speeds = torch.cat([m.U_T, m.U_guarded], -1)[..., None]
        W_x, W_y = (speeds * trig).sum(-2).split_with_sizes(_TWO, -1)
        U_A, direction = torch.hypot(W_x, W_y), safe_atan2(W_y, W_x)
    else:  # as complex numbers W_x + i W_y: fewer operations
        W = torch.polar(m.U_T, m.zeta) + torch.polar(m.U_guarded, course)
        U_A, direction = W.abs(), W.angle()
    # the angle before reduction to [0, 2 pi): from the relative 'from' vector; below the
    # speed guard the true wind's; without true wind (wins) the drift angle's
    angle = torch.where(m.slow, m.zeta, direction) - m.psi
    angle = torch.where(m.U_T < k.speed_guard, m.beta_hat, angle)
    return RelativeWind(U_A, torch.remainder(angle, k.two_pi))


def relative_wind(u, v, psi, U_T, zeta) -> RelativeWind:
    """True wind to relative wind at midship, with the simulator's low-speed guards.

    u, v [m/s] midship body velocity, psi [rad] heading, U_T [m/s], zeta [rad].
    """
    return as_channels(relative_wind_of(motion_of_channels(u, v, None, None, psi=psi, U_T=U_T, zeta=zeta)))


# Fujiwara's coefficients by harmonic: rows cos(k aoa) for k = 1, 3, 5, 2 (C_X) and sin(k aoa)
# for k = 1, 3, 5, 2 (C_Y, C_N); columns (X_A, Y_A, N_A) / U_A^2, each coefficient times
# 1/2 rho_air and its area (A_T, A_L, A_L L_wind)
_HARMONICS = (1.0, 3.0, 5.0, 2.0)
_AREAS = (("half_rho_air", "A_T"), ("half_rho_air", "A_L"), ("half_rho_air", "A_L", "L_wind"))
_FUJIWARA = Rows(tuple(None if name is None else (name,) + area for name, area in zip(row, _AREAS))
                  for row in (("X1", None, None), ("X3", None, None), ("X5", None, None), (None, None, None),
                              (None, "Y1", "N1"), (None, "Y3", "N3"), (None, "Y5", None), (None, None, "N2")))
_CONSTANT = (("X0",) + _AREAS[0], None, None)
# aoa = 2 pi - gamma_A: cos(k aoa) = sin(pi/2 - k gamma_A), sin(k aoa) = sin(-k gamma_A)
_PHASES = (_HALF_PI,) * 4 + (None,) * 4
_MINUS_HARMONICS = tuple(-h for h in _HARMONICS) * 2
_WIND = (_PHASES, _MINUS_HARMONICS, _CONSTANT, _FUJIWARA)


def wind_forces(U_A: torch.Tensor, gamma_A: torch.Tensor, c) -> torch.Tensor:
    """(X_A [N], Y_A [N], N_A [N m]) (..., 3) from U_A [m/s], gamma_A [rad], each (..., 1);
    see `wind_force`."""
    phases, harmonic, constant, matrix = coefficient_vectors(c, _WIND, U_A)
    harmonics = torch.sin(torch.addcmul(phases, gamma_A, harmonic))  # (..., 8)
    if harmonics.dim() == 2:
        C = torch.addmm(constant, harmonics, matrix)
    else:
        C = torch.addmm(constant, harmonics.reshape(-1, 8), matrix).view(U_A.shape[:-1] + (3,))
    return C * (U_A * U_A)


def wind_force(U_A, gamma_A, c):
    """X_A [N], Y_A [N], N_A [N m] from the relative wind (U_A [m/s], gamma_A [rad]).

    `c` provides rho_air, A_T, A_L, L_wind and Fujiwara's X0..X5, Y1..Y5, N1..N3.
    C_X = X0 + sum_k X_k cos(k aoa), C_Y = sum_k Y_k sin(k aoa), C_N = sum_k N_k sin(k aoa),
    aoa = 2 pi - gamma_A, evaluated as one (..., 8) x (8, 3) product; X_A = 1/2 rho_air
    A_T U_A^2 C_X, Y_A = 1/2 rho_air A_L U_A^2 C_Y, N_A = 1/2 rho_air A_L L_wind U_A^2 C_N.
    """
    c = view_of(c, U_A)
    return wind_forces(U_A[..., None], gamma_A[..., None], c).unbind(-1)
