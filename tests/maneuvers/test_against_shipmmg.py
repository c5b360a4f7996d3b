"""KVLCC2 L7 maneuvers of `sysid.maneuvers` against shipmmg as an independent simulator.

Same ship (shipmmg's conventions, as in tests/test_shipmmg_kvlcc2.py: its wake form and
x'_P, x_G = 0), same approach speed and propeller revolutions (shipmmg's example: u0 =
2.29 * 0.512 m/s, 17.95 rps), same step dt = 0.1 s and rudder rate (15.8 deg/s). Ours: the
closed-loop orders and classical RK4 with the rudder held at its mean over each step.
shipmmg: its own right-hand side integrated by scipy's DOP853 at tolerance 1e-10 through
its cubic spline of the rudder samples. The indices of both trajectories are computed by
our index functions.

Turning: shipmmg runs the rate-limited rudder ramp to 35 deg (open loop; a turning circle
never reverses). Zig-zag: the reversals are decided here, on the same grid as ours (the
first sample at which the heading deviation has reached the check angle on the side the
rudder turns to; the rudder ramps from there), each leg one shipmmg simulation from the
state at that sample. (shipmmg's own `zigzag_test_mmg_3dof` restarts each leg from u, v, r,
x, y of the sample before the switch and integrates at scipy's default tolerance; its first
overshoot of the 10/10 differs from this one by 12 %, so it is not the reference here.)
"""
from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("shipmmg.mmg_3dof", reason="shipmmg not installed (a dev extra: pip install -e '.[dev]')")
import shipmmg.mmg_3dof as shipmmg  # noqa: E402

from shipmmg_kvlcc2 import NPS, U0, ship_like_shipmmg, shipmmg_params  # noqa: E402

from sysid import MMG  # noqa: E402
from sysid.maneuvers import Conditions, Side, TurningCircle, ZigZag, simulate_maneuvers  # noqa: E402
from sysid.maneuvers.indices import Track, advance, tactical_diameter, transfer, zigzag_overshoots  # noqa: E402

RATE, DT, DURATION = 15.8, 0.1, 70.0  # deg/s, s, s
TOL = dict(method="DOP853", rtol=1e-10, atol=1e-10)
AGREE = 0.005  # relative


def _legs(ship, rudder_deg: float, check_deg: float | None, side: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t (T,), states (T, 6) x u y v psi r, rudder (T,) [rad]) of shipmmg under the
    rate-limited rudder, reversed on the grid when the heading reaches the check angle
    (never for `check_deg` None)."""
    basic, man = shipmmg_params(ship)
    t = np.arange(int(round(DURATION / DT)) + 1) * DT
    states, rudder = np.zeros((len(t), 6)), np.zeros(len(t))
    start, order, angle = 0, side, 0.0
    initial = dict(u0=U0, v0=0.0, r0=0.0, x0=0.0, y0=0.0, ψ0=0.0)
    step = math.radians(RATE) * DT
    while True:
        n = len(t) - start
        delta = np.empty(n)
        delta[0] = angle
        for i in range(1, n):
            delta[i] = delta[i - 1] + np.clip(order * math.radians(rudder_deg) - delta[i - 1], -step, step)
        sol = shipmmg.simulate_mmg_3dof(basic, man, t[start:], delta, np.full(n, NPS), ρ=ship["rho"],
                                        t_eval=t[start:], **initial, **TOL)
        assert sol.success
        u, v, r, x, y, psi = sol.y[:6]
        leg = np.stack([x, u, y, v, psi, r], 1)
        reached = [] if check_deg is None else np.nonzero(order * psi[1:] >= math.radians(check_deg))[0]
        j = int(reached[0]) + 1 if len(reached) else n
        states[start:start + j], rudder[start:start + j] = leg[:j], delta[:j]
        if j == n:
            return t, states, rudder
        start += j
        states[start], rudder[start] = leg[j], delta[j]
        initial = dict(u0=u[j], v0=v[j], r0=r[j], x0=x[j], y0=y[j], ψ0=psi[j])
        angle, order = delta[j], -order


@pytest.fixture(scope="module")
def ship(tmp_path_factory):
    return ship_like_shipmmg(tmp_path_factory.mktemp("kvlcc2"), x_G=0.0)


@pytest.fixture(scope="module")
def ours(ship):
    maneuvers = [TurningCircle(35.0, Side.STARBOARD), TurningCircle(35.0, Side.PORT), ZigZag(10.0, 10.0),
                 ZigZag(20.0, 20.0)]
    results = simulate_maneuvers(MMG(ship), maneuvers, Conditions(U0, NPS, RATE, DT, DURATION))
    return {r.maneuver.name: r for r in results}


@pytest.mark.parametrize("side", [Side.STARBOARD, Side.PORT])
def test_turning_circle_agrees_with_shipmmg(ship, ours, side):
    t, states, _ = _legs(ship, 35.0, None, side.sign)
    theirs = Track.of(t, states)
    mine = ours[f"turning_35_{side.value}"].indices
    for name, index in (("advance_m", advance), ("transfer_m", transfer), ("tactical_diameter_m", tactical_diameter)):
        assert getattr(mine, name) == pytest.approx(index(theirs), rel=AGREE), name
    assert 2.0 * ship["L_pp"] < mine.tactical_diameter_m < 4.0 * ship["L_pp"]  # a real turn: KVLCC2's 3 L or so


@pytest.mark.parametrize("angle", [10.0, 20.0])
def test_zigzag_overshoots_agree_with_shipmmg(ship, ours, angle):
    t, states, rudder = _legs(ship, angle, angle, 1.0)
    theirs = zigzag_overshoots(Track.of(t, states), angle, rudder)
    mine = ours[f"zigzag_{angle:g}_{angle:g}_starboard"].indices
    assert mine.first_overshoot_deg == pytest.approx(theirs[0], rel=AGREE)
    assert mine.second_overshoot_deg == pytest.approx(theirs[1], rel=AGREE)
    assert 1.0 < mine.first_overshoot_deg < angle  # a real overshoot, within the zig-zag's size
