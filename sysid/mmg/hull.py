"""Hull forces: Yoshimura's unified low-speed model (paper Eq. 26; docs: MMG equations).

Cross-flow drag integrals are evaluated in closed form (no quadrature), written so that
no term cancels catastrophically when the yaw rate is small (float32 safe).
"""
from __future__ import annotations

import math

import torch

from sysid.mmg.coefficients import coefficient_matrix, coefficient_vector, view_of
from sysid.mmg.guards import SPEED_GUARD, safe_atan2, safe_div

SIMPSON_POINTS = 100  # the lab simulator's sample count


def simpson_avg_weights(points: int = SIMPSON_POINTS) -> torch.Tensor:
    """Quadrature weights (per unit spacing h) of SciPy's old ``simps(even='avg')``.

    For an even number of points: the mean of (Simpson on the first N-1 points +
    trapezoid on the last interval) and (trapezoid on the first + Simpson on the last N-1).
    """
    def simpson(n):  # odd n points, weights per h
        w = torch.ones(n, dtype=torch.float64)
        w[1:-1:2], w[2:-1:2] = 4.0, 2.0
        return w / 3.0
    if points % 2:
        return simpson(points)
    first = torch.zeros(points, dtype=torch.float64)
    last = torch.zeros(points, dtype=torch.float64)
    first[:-1] += simpson(points - 1)
    first[-2:] += 0.5
    last[1:] += simpson(points - 1)
    last[:2] += 0.5
    return 0.5 * (first + last)


def crossflow_integrals_simpson(v: torch.Tensor, b: torch.Tensor, L: torch.Tensor,
                                points: int = SIMPSON_POINTS) -> tuple[torch.Tensor, torch.Tensor]:
    """The same integrals as `crossflow_integrals` by the lab's 100-point Simpson rule
    (to reproduce its simulator to round-off; differs from exact by <= 2e-5 kgf)."""
    unit = torch.linspace(-0.5, 0.5, points, dtype=v.dtype, device=v.device)
    x = unit * L  # (points,)
    w = v[..., None] + b[..., None] * x
    f = w.abs() * w
    weights = simpson_avg_weights(points).to(dtype=v.dtype, device=v.device) * (L / (points - 1))
    return f @ weights, (f * x) @ weights


def crossflow_integrals(v: torch.Tensor, b: torch.Tensor, L, L3=None, half=None) -> tuple[torch.Tensor, torch.Tensor]:
    """Exact cross-flow integrals over the hull, x in [-L/2, L/2] [m].

    With w(x) = v + b x (local lateral velocity [m/s], b = C_r r [1/s]) returns
    I1 = ∫ |w| w dx [m^3/s^2] and I2 = ∫ |w| w x dx [m^4/s^2]. `L3` is L**3 when known.
    v and b broadcast: the hull's two integrals (C_rY and C_rN) come from one call on
    b (..., 2).
    """
    L3 = L**3 if L3 is None else L3
    half = 0.5 * L if half is None else half  # m
    bh = b * half
    w1 = v - bh
    w2 = v + bh
    w12 = w1 * w2
    same_sign = w12 >= 0  # no zero crossing along the hull (includes b = 0)
    sign = torch.where(v >= 0, 1.0, -1.0).to(v.dtype)
    # no crossing: |w| w = s w^2, polynomial integrals, no division by b
    bb = b * b
    i1_same = sign * (v * v * L + bb * L3 / 12.0)
    i2_same = sign * v * b * L3 / 6.0
    # crossing (w1, w2 of opposite signs): |w2|^3 - |w1|^3 = sign(b) (w1^3 + w2^3) and
    # w1^3 + w2^3 = 2 v (w1^2 - w1 w2 + w2^2): no cancellation, and |b| L/2 >= |v|
    crossing = ~same_sign
    quad_form = w1 * w1 - w12 + w2 * w2
    two_v = 2.0 * v
    i1_cross = safe_div(two_v * quad_form, 3.0 * b.abs(), crossing)
    moment = (w1**4 + w2**4) / 4.0 - two_v * v * quad_form / 3.0
    i2_cross = safe_div(torch.sign(b) * moment, bb, crossing)
    return torch.where(same_sign, i1_same, i1_cross), torch.where(same_sign, i2_same, i2_cross)


# the hull's forces as (..., 8) products of the motion times an (8, 3) coefficient matrix:
# (X0 u U, v r, v |u|, r u, v u, r |u|, I1, I2) -> (X_H, Y_H, N_H)
_LEFT = torch.tensor([1, 1, 2, 1, 2])   # of (u, v, r, |u|)
_RIGHT = torch.tensor([2, 3, 0, 0, 3])
_HULL = (("q", None, None),
         (("q", "X_vr", "L_pp"), None, None),
         (None, ("q", "Y_v"), None),
         (None, ("q", "Y_r", "L_pp"), None),
         (None, None, ("qL", "N_v")),
         (None, None, ("qL", "N_r", "L_pp")),
         (None, (-1.0, "q", "C_D_L"), None),
         (None, None, (-1.0, "qL", "C_D_L2")))
_FIRST_LANE = torch.tensor([True, False])


def hull_force(u: torch.Tensor, v: torch.Tensor, r: torch.Tensor, c,
               quadrature: str = "exact") -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """X_H [N], Y_H [N], N_H [N m about midship] from u, v (midship) [m/s], r [rad/s].

    `c` carries the coefficients (`Coefficients` or its values view): L_pp, d, rho, X_0F,
    X_0A, X_vr, Y_v, Y_r, N_v, N_r, C_D, C_rY, C_rN. `quadrature` is "exact" (closed form)
    or "simpson" (the lab simulator's rule). With q = 1/2 rho L d:
    X_H = q (X0(beta) u U + X_vr v r L), Y_H = q (Y_v v |u| + Y_r r L u - C_D/L I1),
    N_H = q L (N_v v u + N_r r L |u| - C_D/L^2 I2).
    """
    c = view_of(c, u)
    L = c.L_pp
    U = torch.hypot(u, v)
    U_guarded = torch.where(U < SPEED_GUARD, 1e-7, U)
    beta_hat = safe_atan2(v, u)  # = -beta of the usual convention, (-pi, pi]
    X0 = c.X_0F + c.dX_0 * beta_hat.abs() / math.pi
    if quadrature == "simpson":
        i1, _ = crossflow_integrals_simpson(v, c.C_rY * r, L)
        _, i2 = crossflow_integrals_simpson(v, c.C_rN * r, L)
        integrals = torch.stack([i1, i2], -1)
    else:  # both cross-flow corrections in one pass: b (..., 2) = (C_rY r, C_rN r)
        b = r[..., None] * coefficient_vector(c, ("C_rY", "C_rN"), r)
        i1s, i2s = crossflow_integrals(v[..., None], b, L, c.L_pp3, c.half_L)
        integrals = (torch.stack([i1s[..., 0], i2s[..., 1]], -1) if torch.compiler.is_compiling()
                     else torch.where(_FIRST_LANE, i1s, i2s))  # (I1 of C_rY, I2 of C_rN)
    au = u.abs()
    if torch.compiler.is_compiling():  # no tensor constants in traced loop bodies
        pairs = torch.stack([v * r, v * au, r * u, v * u, r * au], -1)
    else:
        basis = torch.stack([u, v, r, au], -1)
        pairs = basis.index_select(-1, _LEFT) * basis.index_select(-1, _RIGHT)
    motion = torch.cat([(X0 * u * U_guarded)[..., None], pairs, integrals], -1)
    shape = motion.shape
    forces = (motion.reshape(-1, 8) @ coefficient_matrix(c, _HULL, u)).view(shape[:-1] + (3,))
    return forces.unbind(-1)
