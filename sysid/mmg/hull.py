"""Hull forces: Yoshimura's unified low-speed model (paper Eq. 26; docs: MMG equations).

Cross-flow drag integrals are evaluated in closed form (no quadrature), written so that
no term cancels catastrophically when the yaw rate is small (float32 safe).
"""
from __future__ import annotations

import torch

from sysid.mmg.coefficient_lookup import coefficient_matrix, coefficient_vectors, view_of
from sysid.mmg.guards import safe_div
from sysid.mmg.motion import Motion, motion_of_channels

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


# the hull's forces as an (..., 8) feature vector times an (8, 3) coefficient matrix:
# features (v, v, v, r, r, X0 U) * (u, |u|, r, u, |u|, u), then (I1, I2)
_HULL = ((None, None, ("qL", "N_v")),             # v u
         (None, ("q", "Y_v"), None),              # v |u|
         (("q", "X_vr", "L_pp"), None, None),     # v r
         (None, ("q", "Y_r", "L_pp"), None),      # r u
         (None, None, ("qL", "N_r", "L_pp")),     # r |u|
         ("q", None, None),                       # X0 U u
         (None, (-1.0, "q", "C_D_L"), None),      # I1
         (None, None, (-1.0, "qL", "C_D_L2")))    # I2
# the cross-flow integrals as lanes (I1 of b = C_rY r, I2 of b = C_rN r), h = L/2 [m]:
# no zero crossing along the hull: sign(v) (a v^2 + g v b + c b^2) with
# a = (L, 0), g = (0, L^3/6), c = (L^3/12, 0);
# crossing (|b| h > |v|): b |b| P(t), t = v / b, P(t) = (2/3) t^3 + 2 h^2 t (I1) and
# h^4/2 + h^2 t^2 - t^4/6 (I2): every term bounded by |t| <= h, no cancellation
_SAME_V2 = ("L_pp", None)
_SAME_VB = (None, (1.0 / 6.0, "L_pp3"))
_SAME_B2 = ((1.0 / 12.0, "L_pp3"), None)
_HORNER = ((None, -1.0 / 6.0),                            # t^4
           (2.0 / 3.0, None),                             # t^3
           (None, ("half_L", "half_L")),                  # t^2
           ((2.0, "half_L", "half_L"), None),             # t
           (None, (0.5, "half_L", "half_L", "half_L", "half_L")))  # 1
_CROSSFLOW = (("C_rY", "C_rN"), _SAME_V2, _SAME_VB, _SAME_B2) + _HORNER


def crossflow_lanes(v: torch.Tensor, r: torch.Tensor, c, k, smooth: bool) -> torch.Tensor:
    """(..., 2) = (I1 of b = C_rY r [m^3/s^2], I2 of b = C_rN r [m^4/s^2]), the integrals of
    `crossflow_integrals` the hull reads, in one lane pass; v [m/s], r [rad/s] (..., 1);
    `k` the forward's constants (`sysid.mmg.motion.constants`)."""
    Cr, same_v2, same_vb, same_b2, *horner = coefficient_vectors(c, _CROSSFLOW, v)
    b = r * Cr
    b_abs = b.abs()
    crossing = v.abs() < b_abs * c.half_L  # w = v + b x changes sign along the hull
    same = torch.addcmul(same_v2 * v, same_vb, b) * v
    same = torch.addcmul(same, same_b2, b * b) * torch.sign(v)
    t = v / (torch.where(crossing, b, k.one) if smooth else b)
    P = horner[0]
    for row in horner[1:]:
        P = torch.addcmul(row, P, t)
    return torch.where(crossing, P * (b * b_abs), same)


def hull_forces(m: Motion, c, quadrature: str = "exact") -> torch.Tensor:
    """(X_H [N], Y_H [N], N_H [N m about midship]) (..., 3) of a `Motion` (see `hull_force`)."""
    u, v, r = m.u, m.v, m.r
    X0 = torch.addcmul(c.X_0F, c.dX_0_pi, m.beta_hat.abs())  # beta_hat = -beta, (-pi, pi]
    if quadrature == "simpson":
        i1, _ = crossflow_integrals_simpson(v[..., 0], c.C_rY * r[..., 0], c.L_pp)
        _, i2 = crossflow_integrals_simpson(v[..., 0], c.C_rN * r[..., 0], c.L_pp)
        integrals = torch.stack([i1, i2], -1)
    else:
        integrals = crossflow_lanes(v, r, c, m.k, m.smooth)
    u_abs = u.abs()
    products = torch.cat([v, v, v, r, r, X0 * m.U_guarded], -1) * torch.cat([u, u_abs, r, u, u_abs, u], -1)
    return torch.cat([products, integrals], -1) @ coefficient_matrix(c, _HULL, u)


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
    return hull_forces(motion_of_channels(u, v, r, c), c, quadrature).unbind(-1)
