"""KVLCC2 L7 with the standard MMG model against an independent implementation, shipmmg.

Both models are integrated by the same fixed-step classical RK4 on the same time grid
(`FixedStepRK4`, handed to scipy's `solve_ivp`, which shipmmg calls) with the same rudder and
propeller inputs (shipmmg's natural cubic splines through the input samples). The two
integrations then take the same steps at the same times, so any difference comes from the
models; where the models are the same it is the round-off of two codings of one formula
(see `ROUND_OFF`). (An adaptive solver would choose its steps from each model's own
round-off, and its tolerance, not the models, would set the gap.) shipmmg (0.0.11) differs from Yasukawa & Yoshimura (2015)
in three documented conventions, each tested here:

1. wake: w_P = w_P0 exp(-4 beta_P^2) and x'_P = -0.650, where the ship file follows the
   paper's C_1/C_2 correction with x'_P = -0.48 (values recalled, not checked against the
   paper on this machine: see the ship file's header) -> our "standard_gaussian_wake"
   family with x_P = -0.650 reproduces shipmmg; the paper's form is checked against its
   formula.
2. U and beta use the lateral velocity at x = -x_G (v_m - x_G r) instead of midship v_m
   -> with x_G = 0 the models agree to round-off; with x_G = 0.25 m the gap is real and bounded.
3. its force-breakdown helper returns Y_R = -(1 - t_R) F_N cos(delta) (its ODE right-hand
   side uses the paper's -(1 + a_H) F_N cos(delta)) -> compared with that factor.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from scipy.integrate import DenseOutput, OdeSolver, solve_ivp
from scipy.interpolate import CubicSpline

from sysid import MMG, load_ship, state_derivative
from sysid.mmg.families import family

shipmmg = pytest.importorskip(
    "shipmmg.mmg_3dof", reason="shipmmg not installed (a dev extra: pip install -e '.[dev]')")

from shipmmg_kvlcc2 import NPS, U0, ship_like_shipmmg, shipmmg_params  # noqa: E402

# Relative agreement of two codings of the same model integrated on the same grid: each
# right-hand side evaluation agrees to a few ulp (relative 1e-16 to 1e-15), and the
# manoeuvres' dynamics are stable, so the trajectories stay within a few 1e-15 of each
# other (measured: at most 2.2e-15 over the channels of both manoeuvres). 1e-12 leaves a
# margin of several hundred for any IEEE double libm, while a convention that differs
# between the models shows as 1e-3 (the x_G test below).
ROUND_OFF = 1e-12


class FixedStepRK4(OdeSolver):
    """Classical RK4 (1/6, 1/3, 1/3, 1/6) with a fixed step, as a `solve_ivp` method.

    Steps end at t0 + k * step (the last one at t_bound); between the ends of a step the
    dense output interpolates linearly and gives the step's ends exactly.
    """

    def __init__(self, fun, t0, y0, t_bound, vectorized=False, step=0.25, **unused):
        super().__init__(fun, t0, y0, t_bound, vectorized)
        self.t0, self.fixed_step, self.steps = t0, step, 0
        self.y_old = None

    def _step_impl(self):
        t, y = self.t, self.y
        t_new = min(self.t0 + (self.steps + 1) * self.fixed_step, self.t_bound)
        h = t_new - t
        k1 = self.fun(t, y)
        k2 = self.fun(t + 0.5 * h, y + 0.5 * h * k1)
        k3 = self.fun(t + 0.5 * h, y + 0.5 * h * k2)
        k4 = self.fun(t_new, y + h * k3)
        self.y_old, self.t, self.steps = y, t_new, self.steps + 1
        self.y = y + (k1 + 2.0 * (k2 + k3) + k4) * (h / 6.0)
        return True, None

    def _dense_output_impl(self):
        return _Linear(self.t_old, self.t, self.y_old, self.y)


class _Linear(DenseOutput):
    def __init__(self, t_old, t, y_old, y):
        super().__init__(t_old, t)
        self.y_old, self.y = y_old, y

    def _call_impl(self, t):
        t = np.asarray(t, dtype=float)
        share = (t - self.t_old) / (self.t - self.t_old)
        out = self.y_old[:, None] + np.atleast_1d(share) * (self.y - self.y_old)[:, None]
        out[:, np.atleast_1d(t == self.t_old)] = self.y_old[:, None]
        out[:, np.atleast_1d(t == self.t)] = self.y[:, None]
        return out if t.ndim else out[:, 0]


def _solver(time):
    """`solve_ivp` options: `FixedStepRK4` with the grid's step [s]."""
    return dict(method=FixedStepRK4, step=float(time[1] - time[0]))


def _ours(ship, time, delta, nps):
    """Our model's trajectory, same augmented state and splines as shipmmg's."""
    model = MMG(ship)
    d_delta = CubicSpline(time, delta, bc_type="natural").derivative()
    d_nps = CubicSpline(time, nps, bc_type="natural").derivative()

    def rhs(t, y):
        u, v, r, x, y0, psi, dl, n = y
        state = torch.tensor([[x, u, y0, v, psi, r]], dtype=torch.float64)
        inputs = torch.tensor([[n, dl, 0.0, 0.0]], dtype=torch.float64)
        with torch.no_grad():
            d = state_derivative(state, model(state, inputs).total, model.coefficients)[0].tolist()
        return [d[1], d[3], d[5], d[0], d[2], d[4], float(d_delta(t)), float(d_nps(t))]

    sol = solve_ivp(rhs, (time[0], time[-1]), [U0, 0, 0, 0, 0, 0, delta[0], nps[0]],
                    t_eval=time, **_solver(time))
    assert sol.success
    return sol.y[:6]


def _theirs(ship, time, delta, nps):
    basic, man = shipmmg_params(ship)
    sol = shipmmg.simulate_mmg_3dof(basic, man, time, delta, nps, u0=U0, ρ=ship["rho"],
                                    t_eval=time, **_solver(time))
    assert sol.success
    return sol.y[:6]


def _relative_gap(ours, theirs):
    """Per channel (u, v, r, x, y, psi): max |ours - theirs| / max |theirs|."""
    return np.abs(ours - theirs).max(1) / np.abs(theirs).max(1)


def _turning(duration=200.0):
    time = np.linspace(0.0, duration, int(duration * 2) + 1)
    return time, np.full_like(time, math.radians(35.0)), np.full_like(time, NPS)


def _zigzag(ship, duration=80.0):
    """shipmmg's own 10/10 zigzag rudder schedule (its heading-triggered switching)."""
    time = np.linspace(0.0, duration, int(duration * 4) + 1)
    basic, man = shipmmg_params(ship)
    delta = shipmmg.zigzag_test_mmg_3dof(basic, man, math.radians(10), math.radians(10), time,
                                         np.full_like(time, NPS), δ_rad_rate=math.radians(15.8),
                                         u0=U0, ρ=ship["rho"])[0]
    delta = np.asarray(delta)
    switches = np.count_nonzero(np.diff(np.sign(np.diff(delta))) != 0)
    assert delta.min() < math.radians(-9.9) and delta.max() > math.radians(9.9) and switches >= 4  # it zigzags
    return time, delta, np.full_like(time, NPS)


@pytest.mark.slow
@pytest.mark.parametrize("maneuver", ["turning35", "zigzag10"])
def test_trajectories_agree_with_shipmmg(tmp_path, maneuver):
    ship = ship_like_shipmmg(tmp_path, x_G=0.0)
    time, delta, nps = _turning() if maneuver == "turning35" else _zigzag(ship)
    ours, theirs = _ours(ship, time, delta, nps), _theirs(ship, time, delta, nps)
    gap = _relative_gap(ours, theirs)
    assert gap.max() < ROUND_OFF, dict(zip("u v r x y psi".split(), gap))
    # and the maneuver is a real one: a 35-deg turn heads round past 180 deg in 200 s
    if maneuver == "turning35":
        assert theirs[5, -1] > math.pi


def test_shipmmg_midship_convention_is_the_only_gap_with_x_G(tmp_path):
    """Convention 2: with x_G = 0.25 m shipmmg evaluates U and beta at x = -x_G; the gap
    appears, stays small, and is gone with x_G = 0 (previous test)."""
    ship = ship_like_shipmmg(tmp_path, x_G=0.25)
    time, delta, nps = _turning(100.0)
    gap = _relative_gap(_ours(ship, time, delta, nps), _theirs(ship, time, delta, nps))
    assert 1e-5 < gap.max() < 0.05


def test_force_components_against_shipmmg(tmp_path):
    """Forces and inflow quantities at states along a turn, with convention 3 for Y_R."""
    ship = ship_like_shipmmg(tmp_path, x_G=0.0)
    time, delta, nps = _turning(60.0)
    u, v, r = _theirs(ship, time, delta, nps)[:3]
    basic, man = shipmmg_params(ship)
    ref = shipmmg.get_sub_values_from_simulation_result(
        u, v, r, delta, nps, basic, man, ρ=ship["rho"], return_all_vals=True)
    (X_H, X_R, X_P, Y_H, Y_R, N_H, N_R, _U, _beta, _vd, _rd, _bP, w_P, J, K_T, _bR, _gR,
     v_R, u_R, _UR, alpha_R, F_N) = map(np.asarray, ref)
    model = MMG(ship)
    zeros = np.zeros_like(u)
    state = torch.tensor(np.stack([zeros, u, zeros, v, zeros, r], -1))
    inputs = torch.tensor(np.stack([nps, delta, zeros, zeros], -1))
    f = model(state, inputs)
    c = model.coefficients
    prop = family("propeller", ship.models["propeller"]).inflow(state[:, 1], state[:, 3], state[:, 5],
                                                                 inputs[:, 0], c)
    from sysid.mmg.rudder_standard import rudder_inflow_standard
    rud = rudder_inflow_standard(state[:, 1], state[:, 3], state[:, 5], inputs[:, 0], inputs[:, 1], c, prop)
    factor = (1 - ship["t_R"]) / (1 + ship["a_H"])  # convention 3
    pairs = [(f.hull[:, 0], X_H), (f.hull[:, 1], Y_H), (f.hull[:, 2], N_H), (f.propeller[:, 0], X_P),
             (f.rudder[:, 0], X_R), (f.rudder[:, 1] * factor, Y_R), (f.rudder[:, 2], N_R),
             (1 - prop.one_minus_wP, w_P), (prop.J, J), (prop.K_T, K_T), (rud.u_R, u_R),
             (rud.v_R, v_R), (rud.alpha_R, alpha_R), (rud.F_N, F_N)]
    for ours, theirs in pairs:
        np.testing.assert_allclose(ours.numpy(), theirs, rtol=1e-10, atol=1e-10 * np.abs(theirs).max())
    assert np.all(f.wind.numpy() == 0.0) and np.all(f.propeller[:, 1:].numpy() == 0.0)


def test_paper_wake_is_the_documented_formula():
    """Convention 1, the paper's side: 1 - w_P = (1 - w_P0)[1 + (1 - exp(-C_1|beta_P|))(C_2 - 1)]."""
    ship = load_ship("kvlcc2_l7")
    c = MMG(ship).coefficients
    u = torch.tensor([1.0, 1.0, 1.0, 1.0], dtype=torch.float64)
    v = torch.tensor([0.0, -0.2, 0.2, 0.05], dtype=torch.float64)
    r = torch.tensor([0.0, 0.0, 0.0, -0.03], dtype=torch.float64)
    n = torch.full_like(u, NPS)
    prop = family("propeller", "standard").inflow(u, v, r, n, c)
    for k in range(4):
        U = math.hypot(float(u[k]), float(v[k]))
        beta_P = math.atan2(-float(v[k]), float(u[k])) - ship["x_P"] * float(r[k]) * ship["L_pp"] / U
        C_2 = ship["C_2_plus"] if beta_P > 0 else ship["C_2_minus"]
        expected = (1 - ship["w_P0"]) * (1 + (1 - math.exp(-ship["C_1"] * abs(beta_P))) * (C_2 - 1))
        assert float(prop.one_minus_wP[k]) == pytest.approx(expected, rel=1e-14)
        J = float(u[k]) * expected / (NPS * ship["D"])
        assert float(prop.K_T[k]) == pytest.approx(ship["k0"] + ship["k1"] * J + ship["k2"] * J * J, rel=1e-14)
