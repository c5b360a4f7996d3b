"""F_MMG of the Esso Osaka's families with its Jacobian with respect to the state, by hand.

`forces_with_tangents` computes, without autograd, what `MMG.total_force` computes for a ship
whose families are Yoshimura's hull (exact cross-flow integrals), the four-quadrant propeller
and rudder and Fujiwara's wind (or no wind), and beside every value its derivative with
respect to the state (x, u, y, v, psi, r): a tangent (..., 6) per lane, carried through each
formula by the chain rule written out here (forward mode by hand, one pass, no autograd).
A training step's backward is then one product of its output gradient with the Jacobian
(`sysid.hybrid.training_rate`), in place of autograd's record of some 200 operations.

Where the model switches (`torch.where` between inflow forms, propeller quadrants, the wake's
clamp, |x| at 0), the derivative is that of the branch the forward takes, as autograd's:
clamp passes the derivative on its closed interval, |x| and sign give sign(x) and 0 at 0,
sqrt(max(x, 0)) gives 0 for x <= 0 (the guards' choice, `sysid.mmg.guards`). At u = v = 0
exactly (the speed guard's inside) the drift angle's derivative is taken as 0; autograd's is
NaN there (the derivative of hypot at 0).

`supported(mmg)` is the boundary: other families (the standard ones), Simpson's quadrature
or coefficients being identified (requiring a gradient) are computed by `MMG` through autograd
instead.
"""
from __future__ import annotations

from typing import NamedTuple

import torch

from sysid.mmg.coefficient_lookup import coefficient_matrix, coefficient_vectors
from sysid.mmg.hull import _CROSSFLOW, _HULL
from sysid.mmg.motion import _FOUR, _SIX, constants
from sysid.mmg.propeller import _LATERAL
from sysid.mmg.rudder import _RUDDER
from sysid.mmg.wind import _WIND

# the families whose derivatives are written out here, by component (wind: or none)
FAMILIES = {"hull": "yoshimura_low_speed", "propeller": "four_quadrant", "rudder": "four_quadrant",
            "wind": "fujiwara"}


def supported(mmg) -> bool:
    """True where `forces_with_tangents` computes `mmg`'s F_MMG: the families of `FAMILIES`
    (wind optional), exact cross-flow integrals, no coefficient that requires a gradient
    (identified coefficients frozen for the hybrid's training are constants here)."""
    models = mmg.ship.models
    if any(models.get(k) != v for k, v in FAMILIES.items() if k != "wind"):
        return False
    if models.get("wind") not in (None, FAMILIES["wind"]):
        return False
    return mmg.quadrature == "exact" and not any(p.requires_grad for p in mmg.coefficients.parameters())


class Tangents(NamedTuple):
    """F_MMG and the relative wind as body-frame components, with their derivatives, each
    derivative laid out (..., 6, k): entry [i, j] is d(output j)/d(state i)."""

    force: torch.Tensor       # (..., 3) = (X, Y, N) [N, N, N m]
    d_force: torch.Tensor     # (..., 6, 3) d(X, Y, N)/d(x, u, y, v, psi, r)
    omega: torch.Tensor       # (..., 2) = U_A (cos gamma_A, sin gamma_A) [m/s]
    d_omega: torch.Tensor     # (..., 6, 2)


class Basis(NamedTuple):
    """Constant tangents in the states' dtype and device (see `basis`)."""

    E: torch.Tensor           # (6, 6) identity: row i is the tangent of state i
    e_u: torch.Tensor         # (6,) rows of E
    e_v: torch.Tensor
    e_psi: torch.Tensor
    e_r: torch.Tensor
    u_col: torch.Tensor       # (6, 1) e_u as a column, and alike
    v_col: torch.Tensor
    r_col: torch.Tensor
    uv: torch.Tensor          # (6,) (0, 1, 0, 1, 0, 0): picks u, v of a state
    vu: torch.Tensor          # (6,) (0, -1, 0, 1, 0, 0) times the state with u, v swapped
    swap_uv: torch.Tensor     # (6,) long: the state's columns with u and v swapped
    hull_first: torch.Tensor  # (6, 5) tangents (columns) of the hull products' first factors v, v, v, r, r
    hull_r: torch.Tensor      # (6, 6) r's tangent in the second factors (u, |u|, r, u, |u|, u)
    psi_of_uvpsi: torch.Tensor  # (3,) (0, 0, 1): psi's tangent over (u, v, psi) (`motion_columns`)


_BASES: dict[tuple, Basis] = {}


def basis(like: torch.Tensor) -> Basis:
    """The `Basis` for states like `like`, made once per dtype and device."""
    key = (like.dtype, like.device)
    found = _BASES.get(key)
    if found is None:
        with torch.inference_mode(False), torch.no_grad():
            kw = {"dtype": like.dtype, "device": like.device}
            E = torch.eye(6, **kw)
            hull_r = torch.zeros(6, 6, **kw)
            hull_r[5, 2] = 1.0
            found = _BASES[key] = Basis(
                E, E[1].clone(), E[3].clone(), E[4].clone(), E[5].clone(),
                E[:, 1:2].clone(), E[:, 3:4].clone(), E[:, 5:6].clone(),
                torch.tensor([0.0, 1.0, 0.0, 1.0, 0.0, 0.0], **kw), torch.tensor([0.0, -1.0, 0.0, 1.0, 0.0, 0.0], **kw),
                torch.tensor([0, 3, 2, 1, 4, 5], device=like.device), E[:, [3, 3, 3, 5, 5]].clone(), hull_r,
                E[4, [1, 3, 4]].clone())
    return found


# tangent directions that depend on coefficients: lateral inflow at the propeller
# v + x_P L r, at the rudder v + l_R r (each d/d(x, u, y, v, psi, r))
_PROPELLER_LATERAL = (None, None, None, 1.0, None, "x_P_L")
_RUDDER_LATERAL = (None, None, None, 1.0, None, "l_R")
# the coefficients the derivatives multiply by, as (1,) vectors (one cached look-up)
_FACTORS = ((2.0, "C_P"), (2.0, "k2"), (2.0, "eps2_one_minus_eta"), (2.0, "eps2_eta"), (2.0, "C_PR"),
            (1.0, "dX_0_pi"), (1.0, "C7"), (1.0, "jet_D2"), (1.0, "kitagawa_jet_eps2"),
            (1.0, "one_minus_tP_rho_D4"), (1.0, "rho_D4"), (1.0, "kappa"))
_CONSTANTS = (_PROPELLER_LATERAL, _RUDDER_LATERAL) + tuple((f,) for f in _FACTORS)


def _col(x: torch.Tensor) -> torch.Tensor:
    """A tangent (..., 6) as one column (..., 6, 1)."""
    return x.unsqueeze(-1)


def _row(x: torch.Tensor) -> torch.Tensor:
    """(..., k) values as (..., 1, k), to scale tangent columns (..., 6, k)."""
    return x.unsqueeze(-2)


class _Factors(NamedTuple):
    """The `_CONSTANTS` as (1,) vectors, in their order."""

    lateral_P: torch.Tensor
    lateral_R: torch.Tensor
    two_C_P: torch.Tensor
    two_k2: torch.Tensor
    two_eps2_one_minus_eta: torch.Tensor
    two_eps2_eta: torch.Tensor
    two_C_PR: torch.Tensor
    dX_0_pi: torch.Tensor
    C7: torch.Tensor
    jet_D2: torch.Tensor
    kitagawa_jet_eps2: torch.Tensor
    one_minus_tP_rho_D4: torch.Tensor
    rho_D4: torch.Tensor
    kappa: torch.Tensor


class _Motion(NamedTuple):
    """The state's velocities and what every family reads of them, with tangents (..., 6)."""

    u: torch.Tensor           # (..., 1) [m/s]
    v: torch.Tensor           # (..., 1) [m/s]
    psi: torch.Tensor         # (..., 1) [rad]
    r: torch.Tensor           # (..., 1) [rad/s]
    slow: torch.Tensor        # (..., 1) bool: inside the speed guard
    Ug: torch.Tensor          # (..., 1) guarded speed [m/s]
    beta_hat: torch.Tensor    # (..., 1) atan2(v, u) [rad]
    sign_u: torch.Tensor      # (..., 1)
    d_Ug: torch.Tensor        # (..., 6)
    d_beta: torch.Tensor      # (..., 6)


class _Propeller(NamedTuple):
    """The propeller's forces and what the rudder's inflow reads of it."""

    force: torch.Tensor          # (..., 3)
    d_force: torch.Tensor        # (..., 6, 3)
    omw: torch.Tensor            # (..., 1) 1 - w_P
    d_omw: torch.Tensor          # (..., 6)
    K_T: torch.Tensor            # (..., 1)
    d_KT: torch.Tensor           # (..., 6)
    n: torch.Tensor              # (..., 1) [rps]
    n2: torch.Tensor             # (..., 1) n^2 [1/s^2]
    turning_ahead: torch.Tensor  # (..., 1) bool: n >= 0
    moving_ahead: torch.Tensor   # (..., 1) bool: u >= 0


class _Wind(NamedTuple):
    """The relative wind: body-frame components, its speed and angle, with tangents (the
    components' own: `omega_tangents`)."""

    omega: torch.Tensor       # (..., 2) [m/s] = U_A (cos gamma_A, sin gamma_A)
    U_A: torch.Tensor         # (..., 1) [m/s]
    d_UA: torch.Tensor        # (..., 6)
    gamma_A: torch.Tensor     # (..., 1) [rad] in [0, 2 pi)
    d_gamma: torch.Tensor     # (..., 6)
    cos_g: torch.Tensor       # (..., 1) cos gamma_A
    sin_g: torch.Tensor       # (..., 1) sin gamma_A


def forces_with_tangents(state: torch.Tensor, inputs: torch.Tensor, c, wind: bool = True) -> Tangents:
    """F_MMG (..., 3) and the relative wind's body-frame components (..., 2), each with its
    Jacobian with respect to state (..., 6) = (x, u, y, v, psi, r); inputs (..., 4) = (n [rps],
    delta [rad], U_T [m/s], zeta [rad]) are constants here. `c` is the coefficients' values
    view; `wind` adds Fujiwara's wind force (the ship has a [wind] section). No autograd is
    recorded (call it under ``torch.no_grad()`` or from an autograd Function's forward)."""
    k = constants(state)
    B = basis(state)
    f = _Factors(*coefficient_vectors(c, _CONSTANTS, state))
    n, delta, U_T, zeta = inputs.split_with_sizes(_FOUR, -1)
    m = motion_tangents(state, k, B)
    hull, d_hull = _hull(m, c, k, B, f)
    P = _propeller(m, n, c, k, B, f)
    rudder, d_rudder = _rudder(m, delta, P, c, k, B, f)
    W = relative_wind_tangents(m, U_T, zeta, k, B.e_psi)
    total = hull + P.force + rudder
    d_total = d_hull + P.d_force + d_rudder
    if wind:
        total, d_total = _wind_force(W, total, d_total, c)
    return Tangents(total, d_total, W.omega, omega_tangents(W))


def _speed_and_drift(u: torch.Tensor, v: torch.Tensor, k):
    """(U, slow, guarded U, beta_hat = atan2(v, u), 1 / U (1 at U = 0)), each (..., 1)."""
    U = torch.hypot(u, v)
    slow = U < k.speed_guard
    return U, slow, torch.where(slow, k.low_speed, U), torch.atan2(v, u), 1.0 / torch.where(U > k.zero, U, k.one)


def motion_tangents(state: torch.Tensor, k, B: Basis) -> _Motion:
    """Speed, guarded speed and drift angle beta_hat = atan2(v, u) [rad], with tangents."""
    _, u, _, v, psi, r = state.split_with_sizes(_SIX, -1)
    U, slow, Ug, beta_hat, inv_U = _speed_and_drift(u, v, k)
    d_Ug = state * (B.uv * torch.where(slow, k.zero, inv_U))          # (u, v) / U
    d_beta = state[..., B.swap_uv] * (B.vu * (inv_U * inv_U))         # (-v, u) / U^2
    return _Motion(u, v, psi, r, slow, Ug, beta_hat, torch.sign(u), d_Ug, d_beta)


def motion_columns(state: torch.Tensor, k) -> _Motion:
    """`motion_tangents` with the tangents over (u, v, psi) alone (..., 3) (the others' are
    zero): what the relative wind reads (`relative_wind_tangents` with `Basis.psi_of_uvpsi`)."""
    _, u, _, v, psi, r = state.split_with_sizes(_SIX, -1)
    U, slow, Ug, beta_hat, inv_U = _speed_and_drift(u, v, k)
    zero = torch.zeros_like(u)
    d_Ug = torch.cat([u, v, zero], -1) * torch.where(slow, k.zero, inv_U)    # (u, v, 0) / U
    d_beta = torch.cat([-v, u, zero], -1) * (inv_U * inv_U)                 # (-v, u, 0) / U^2
    return _Motion(u, v, psi, r, slow, Ug, beta_hat, torch.sign(u), d_Ug, d_beta)


def _crossflow(m: _Motion, c, k, B: Basis) -> tuple[torch.Tensor, torch.Tensor]:
    """The hull's cross-flow integrals I1, I2 (..., 2) and their tangents (..., 6, 2)."""
    v, r = m.v, m.r
    Cr, same_v2, same_vb, same_b2, *horner = coefficient_vectors(c, _CROSSFLOW, v)
    b = r * Cr                                                         # (..., 2) [1/s]
    b_abs = b.abs()
    crossing = v.abs() < b_abs * c.half_L
    sign_v = torch.sign(v)
    same = torch.addcmul(same_v2 * v, same_vb, b) * v
    same = torch.addcmul(same, same_b2, b * b) * sign_v
    t = v / torch.where(crossing, b, k.one)
    P, dP = horner[0], torch.zeros_like(b)
    for row in horner[1:]:
        dP = torch.addcmul(P, dP, t)
        P = torch.addcmul(row, P, t)
    integrals = torch.where(crossing, P * (b * b_abs), same)
    # d/dv, d/db: same sign(v) (2 a v + g b), sign(v) (g v + 2 c b); crossing P'(t) |b|, (2 P - t P') |b|
    I_dv = torch.where(crossing, dP * b_abs, torch.addcmul(2.0 * same_v2 * v, same_vb, b) * sign_v)
    I_dr = torch.where(crossing, torch.addcmul(2.0 * P, dP, -t) * b_abs,
                       torch.addcmul(same_vb * v, 2.0 * same_b2, b) * sign_v) * Cr
    return integrals, torch.addcmul(B.v_col * _row(I_dv), B.r_col, _row(I_dr))   # (..., 6, 2)


def _hull(m: _Motion, c, k, B: Basis, f: _Factors) -> tuple[torch.Tensor, torch.Tensor]:
    """Yoshimura's hull force (..., 3) and its tangents (..., 6, 3): features (v u, v |u|,
    v r, r u, r |u|, X0 U u, I1, I2) times an (8, 3) matrix."""
    u, v, r, Ug, beta_hat, sign_u = m.u, m.v, m.r, m.Ug, m.beta_hat, m.sign_u
    zero = torch.zeros_like(u)
    one = torch.ones_like(u)
    beta_abs = beta_hat.abs()
    X0 = torch.addcmul(c.X_0F, c.dX_0_pi, beta_abs)
    d_X0 = (f.dX_0_pi * torch.sign(beta_hat)) * m.d_beta
    integrals, d_integrals = _crossflow(m, c, k, B)
    u_abs = u.abs()
    X0U = X0 * Ug
    a = torch.cat([v, v, v, r, r, X0U], -1)
    bb = torch.cat([u, u_abs, r, u, u_abs, u], -1)
    hull_matrix = coefficient_matrix(c, _HULL, u)
    hull = torch.cat([a * bb, integrals], -1) @ hull_matrix
    d_X0U = torch.addcmul(Ug * d_X0, X0, m.d_Ug)
    batch = u.shape[:-1]
    d_a = torch.cat([B.hull_first.expand(*batch, 6, 5), _col(d_X0U)], -1)            # (..., 6, 6)
    d_b = torch.addcmul(B.hull_r, B.u_col, _row(torch.cat([one, sign_u, zero, one, sign_u, one], -1)))
    d_products = torch.addcmul(_row(a) * d_b, _row(bb), d_a)
    return hull, torch.cat([d_products, d_integrals], -1) @ hull_matrix            # (..., 6, 3)


def _propeller(m: _Motion, n: torch.Tensor, c, k, B: Basis, f: _Factors) -> _Propeller:
    """The four-quadrant propeller: inflow (wake, advance ratios, K_T), then the forces."""
    u, v, r, Ug, slow, sign_u, e_u = m.u, m.v, m.r, m.Ug, m.slow, m.sign_u, B.e_u
    s_raw = torch.addcmul(v, c.x_P_L, r) / Ug
    s = torch.where(slow, c.slow_lateral_inflow, s_raw)
    d_s = torch.where(slow, k.zero, (f.lateral_P - s_raw * m.d_Ug) / Ug)
    s_abs = s.abs()
    wake = torch.addcmul(c.one_minus_wP0, torch.addcmul(c.tau, c.C_P, s_abs), s_abs)
    forward_u = u > k.zero
    omw = torch.where(forward_u, wake.clamp(k.tiny, k.one), k.one)
    wake_slope = torch.addcmul(c.tau, f.two_C_P, s_abs) * torch.sign(s)
    d_omw = torch.where(forward_u & (wake >= k.tiny) & (wake <= k.one), wake_slope, k.zero) * d_s
    n_stopped = n.abs() < k.tiny
    u_stopped = u.abs() < k.tiny
    nD = n * c.D
    J_s = torch.where(n_stopped, sign_u * k.stopped_ratio, torch.where(u_stopped, k.tiny, u / nD))
    dJs_du = torch.where(n_stopped | u_stopped, k.zero, 1.0 / torch.where(n_stopped, k.one, nD))
    moving_ahead = u >= k.zero
    J = torch.where(moving_ahead, J_s * omw, J_s)
    # dJ = omw dJ_s + J_s d omw (moving ahead), dJ_s = dJs_du e_u
    d_J = torch.addcmul(torch.where(moving_ahead, omw, k.one) * dJs_du * e_u,
                        torch.where(moving_ahead, J_s, k.zero), d_omw)
    K_T_ahead = torch.addcmul(c.k0, torch.addcmul(c.k1, c.k2, J), J)
    upper_line = J_s >= c.C10
    K_T_reverse = torch.where(upper_line, torch.addcmul(c.C6, c.C7, J_s), c.C3)
    turning_ahead = n >= k.zero
    K_T = torch.where(n_stopped, k.zero, torch.where(turning_ahead, K_T_ahead, K_T_reverse))
    d_KTa = torch.addcmul(c.k1, f.two_k2, J) * d_J
    d_KTr = (torch.where(upper_line, f.C7, k.zero) * dJs_du) * e_u
    d_KT = torch.where(n_stopped, k.zero, torch.where(turning_ahead, d_KTa, d_KTr))
    n2 = n * n
    X_P = torch.where(turning_ahead, K_T_ahead * c.one_minus_tP_rho_D4, K_T * c.rho_D4)
    d_XP = torch.where(turning_ahead, f.one_minus_tP_rho_D4 * n2 * d_KTa, f.rho_D4 * n2 * d_KT)
    lateral, d_lateral = _propeller_lateral(J_s, dJs_du, n2, turning_ahead, moving_ahead, c, k)
    propeller = torch.cat([X_P, lateral], -1) * n2
    d_propeller = torch.cat([_col(d_XP), B.u_col * _row(d_lateral)], -1)              # (..., 6, 3)
    return _Propeller(propeller, d_propeller, omw, d_omw, K_T, d_KT, n, n2, turning_ahead, moving_ahead)


def _propeller_lateral(J_s, dJs_du, n2, turning_ahead, moving_ahead, c, k) -> tuple[torch.Tensor, torch.Tensor]:
    """The propeller's lateral force and yaw moment coefficients (..., 2) over n^2 and their
    derivatives with respect to u (..., 2), times n^2."""
    A6, A7, A8, A1, A2, A3, A4, A5, low, high = coefficient_vectors(c, _LATERAL, J_s)
    second = torch.addcmul(A8, torch.addcmul(A7, A6, J_s), J_s)
    below, above = J_s < low, J_s > high
    reverse = torch.where(below, torch.addcmul(A3, A4, J_s), torch.where(above, A5, torch.addcmul(A1, A2, J_s)))
    lateral = torch.where(turning_ahead, torch.where(moving_ahead, k.zero, second), reverse)
    d_second = torch.addcmul(A7, 2.0 * A6, J_s)
    d_reverse = torch.where(below, A4, torch.where(above, k.zero, A2))
    d_lateral = torch.where(turning_ahead, torch.where(moving_ahead, k.zero, d_second), d_reverse) * (dJs_du * n2)
    return lateral, d_lateral


def _rudder(m: _Motion, delta: torch.Tensor, P: _Propeller, c, k, B: Basis,
            f: _Factors) -> tuple[torch.Tensor, torch.Tensor]:
    """The four-quadrant rudder: inflow u_R (Yoshimura, Kitagawa or u), v_R, then F_N; its
    force (..., 3) and tangents (..., 6, 3)."""
    v, r = m.v, m.r
    u_R, d_uR = _rudder_inflow(m, P, c, k, B, f)
    straightening = torch.where(torch.addcmul(v, c.x_R, r) >= k.zero, c.minus_gamma_P, c.minus_gamma_N)
    v_R = straightening * torch.addcmul(v, c.l_R, r)
    alpha_R = delta - torch.atan2(v_R, u_R)
    sin_a, cos_a = torch.sin(alpha_R), torch.cos(alpha_R)
    F_N = torch.addcmul(u_R * u_R, v_R, v_R) * sin_a  # / (1/2 rho A_R f_alpha)
    # dF_N = (2 u_R sin a + v_R cos a) du_R + (2 v_R sin a - u_R cos a) dv_R, dv_R = gamma (e_v + l_R e_r)
    d_FN = torch.addcmul(torch.addcmul(2.0 * u_R * sin_a, v_R, cos_a) * d_uR,
                         torch.addcmul(2.0 * v_R * sin_a, -u_R, cos_a) * straightening, f.lateral_R)
    phases, scale = coefficient_vectors(c, _RUDDER, delta)
    rudder_factor = torch.sin(delta + phases) * scale                 # (..., 3)
    return rudder_factor * F_N, _col(d_FN) * _row(rudder_factor)     # (..., 3), (..., 6, 3)


def _rudder_inflow(m: _Motion, P: _Propeller, c, k, B: Basis, f: _Factors) -> tuple[torch.Tensor, torch.Tensor]:
    """The rudder's longitudinal inflow u_R (..., 1) [m/s]: Yoshimura's form (ahead
    revolutions, K_T > 0), Kitagawa's (else moving ahead) or u, and its tangent (..., 6)."""
    u, n, e_u, omw, d_omw, K_T, d_KT, n2 = m.u, P.n, B.e_u, P.omw, P.d_omw, P.K_T, P.d_KT, P.n2
    u_p = u * omw
    d_up = torch.addcmul(omw * e_u, u, d_omw)
    u_p2 = u_p * u_p
    jet = torch.addcmul(u_p2, K_T * n2, c.jet_D2)
    jet_root = torch.sqrt(jet)  # >= 0 where this branch is taken
    half_over_jet_root = torch.where(jet > k.zero, 0.5 / jet_root, k.zero)
    d_jet_root = torch.addcmul(2.0 * u_p * d_up, n2 * f.jet_D2, d_KT) * half_over_jet_root
    core = torch.addcmul(u_p, c.kappa, jet_root - u_p)
    d_core = torch.addcmul(d_up, f.kappa, d_jet_root - d_up)
    outer = u_p2 * c.eps2_one_minus_eta
    d_outer = (f.two_eps2_one_minus_eta * u_p) * d_up
    yoshimura_sq = torch.addcmul(outer, core * core, c.eps2_eta)
    u_R_yoshimura = torch.sqrt(torch.clamp(yoshimura_sq, min=0.0))
    d_yoshimura = torch.addcmul(d_outer, f.two_eps2_eta * core, d_core) * torch.where(
        yoshimura_sq > k.zero, 0.5 / u_R_yoshimura, k.zero)
    race = K_T.abs() * c.kitagawa_jet_eps2
    race_root = torch.sqrt(race)
    race_slope = torch.where(race > k.zero, (0.5 * f.kitagawa_jet_eps2) * torch.sign(K_T) / race_root, k.zero)
    u1 = torch.addcmul(u_p, n, race_root)
    d_u1 = torch.addcmul(d_up, n * race_slope, d_KT)
    u1_abs = u1.abs()
    s_k = torch.addcmul(torch.addcmul(outer, u1 * u1_abs, c.eps2_eta), c.C_PR, u * u)
    d_sk = torch.addcmul(torch.addcmul(d_outer, f.two_eps2_eta * u1_abs, d_u1), f.two_C_PR * u, e_u)
    s_k_abs = s_k.abs()
    root_k = torch.sqrt(s_k_abs)
    u_R_kitagawa = torch.copysign(root_k, s_k)
    d_kitagawa = d_sk * torch.where(s_k_abs > k.zero, 0.5 / root_k, k.zero)
    yoshimura_form = P.turning_ahead & (K_T > k.zero)
    u_R = torch.where(yoshimura_form, u_R_yoshimura, torch.where(P.moving_ahead, u_R_kitagawa, u))
    d_uR = torch.where(yoshimura_form, d_yoshimura, torch.where(P.moving_ahead, d_kitagawa, e_u))
    return u_R, d_uR


def relative_wind_tangents(m: _Motion, U_T: torch.Tensor, zeta: torch.Tensor, k, e_psi: torch.Tensor) -> _Wind:
    """The relative wind (the lab's guards): speed U_A, angle gamma_A and the body-frame
    components U_A (cos gamma_A, sin gamma_A), with tangents of `m`'s width: over the state
    (`motion_tangents`, e_psi = `Basis.e_psi`) or over (u, v, psi) (`motion_columns`, e_psi =
    `Basis.psi_of_uvpsi`)."""
    psi, Ug, slow, beta_hat, d_Ug, d_beta = m.psi, m.Ug, m.slow, m.beta_hat, m.d_Ug, m.d_beta
    course = psi + beta_hat
    cos_c, sin_c = torch.cos(course), torch.sin(course)
    W_x = torch.addcmul(U_T * torch.cos(zeta), Ug, cos_c)
    W_y = torch.addcmul(U_T * torch.sin(zeta), Ug, sin_c)
    d_course = d_beta + e_psi
    d_Wx = torch.addcmul(cos_c * d_Ug, -Ug * sin_c, d_course)
    d_Wy = torch.addcmul(sin_c * d_Ug, Ug * cos_c, d_course)
    U_A = torch.hypot(W_x, W_y)
    inv_UA = 1.0 / torch.where(U_A > k.zero, U_A, k.one)
    d_UA = torch.addcmul(W_x * d_Wx, W_y, d_Wy) * inv_UA
    direction = torch.atan2(W_y, W_x)
    angle = torch.where(slow, zeta, direction) - psi
    calm = U_T < k.speed_guard
    angle = torch.where(calm, beta_hat, angle)
    gamma_A = torch.remainder(angle, k.two_pi)
    d_direction = torch.addcmul(W_x * d_Wy, -W_y, d_Wx) * (inv_UA * inv_UA)
    d_gamma = torch.where(calm, d_beta, torch.where(slow, k.zero, d_direction) - e_psi)
    cos_g, sin_g = torch.cos(gamma_A), torch.sin(gamma_A)
    omega = torch.cat([U_A * cos_g, U_A * sin_g], -1)
    return _Wind(omega, U_A, d_UA, gamma_A, d_gamma, cos_g, sin_g)


def omega_tangents(W: _Wind) -> torch.Tensor:
    """The tangents (..., 6, 2) of the relative wind's body-frame components omega:
    d(U_A cos g, U_A sin g) = (cos g, sin g) dU_A + U_A (-sin g, cos g) dg."""
    cos_g, sin_g = W.cos_g, W.sin_g
    return torch.addcmul(_col(W.d_UA) * _row(torch.cat([cos_g, sin_g], -1)),
                         _col(W.d_gamma), _row(W.U_A * torch.cat([-sin_g, cos_g], -1)))


def _wind_force(W: _Wind, total: torch.Tensor, d_total: torch.Tensor, c) -> tuple[torch.Tensor, torch.Tensor]:
    """`total` (..., 3) and `d_total` (..., 6, 3) with Fujiwara's wind force C(gamma_A) U_A^2 added."""
    U_A, gamma_A = W.U_A, W.gamma_A
    w_phases, harmonic, constant, matrix = coefficient_vectors(c, _WIND, U_A)
    arguments = torch.addcmul(w_phases, gamma_A, harmonic)                # (..., 8)
    C = torch.addmm(constant, torch.sin(arguments).reshape(-1, 8), matrix).view(U_A.shape[:-1] + (3,))
    dC = (torch.cos(arguments) * harmonic).reshape(-1, 8).mm(matrix).view(U_A.shape[:-1] + (3,))
    U_A2 = U_A * U_A
    total = total + C * U_A2
    d_total = d_total + torch.addcmul(_col(W.d_gamma) * _row(U_A2 * dC), _col(W.d_UA), _row(2.0 * U_A * C))
    return total, d_total


def _hull_linear_terms() -> dict[str, tuple[int, int, tuple]]:
    """The hull coefficients Yoshimura's hull force is linear in, read off `_HULL`: each name
    that is a lone factor of one entry among the products (v u, v |u|, v r, r u, r |u|), and
    nowhere else in the hull (the X_0 U u row, the cross-flow rows and lanes), mapped to
    (its product's column, its force component 0..2 = X, Y, N, the entry's other factors)."""
    found: dict[str, list] = {}
    for row, entries in enumerate(_HULL):
        for component, entry in enumerate(entries):
            for name in (entry,) if isinstance(entry, str) else entry or ():
                if isinstance(name, str):
                    others = tuple(n for n in ((entry,) if isinstance(entry, str) else entry) if n != name)
                    found.setdefault(name, []).append((row, component, others))
    elsewhere = {n for names in _CROSSFLOW for n in names if isinstance(n, str)}
    return {name: places[0] for name, places in found.items()
            if len(places) == 1 and places[0][0] < 5 and name not in elsewhere}


# name -> (product column in (v u, v |u|, v r, r u, r |u|), force component, other factors):
# X_vr (v r, X, q L_pp), Y_v (v |u|, Y, q), Y_r (r u, Y, q L_pp), N_v (v u, N, q L_pp),
# N_r (r |u|, N, q L_pp L_pp) (q = 1/2 rho L_pp d [kg/m], qL = q L_pp [kg])
HULL_LINEAR = _hull_linear_terms()
