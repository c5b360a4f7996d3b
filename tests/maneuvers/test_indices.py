"""Each index definition on analytic trajectories whose indices are known in closed form:
circles (turning), a sine heading (zig-zag), a decelerating straight and curved run (crash
stop); and the IMO limits of MSC.137(76)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from sysid.maneuvers import CrashStop, TurningCircle, ZigZag, maneuver_indices
from sysid.maneuvers.criteria import criteria_for, full_scale_L_over_U, overshoot_limits_10_10
from sysid.maneuvers.indices import (Track, advance, head_reach, initial_turning_distance, speed_loss_ratio,
                                     steady_turning_diameter, tactical_diameter, track_reach, transfer,
                                     zigzag_overshoots)

DEG = math.pi / 180.0


def circle(R: float, turns: float, side: float = 1.0, psi0: float = 0.0, origin=(0.0, 0.0), slow_after: float = 1e9,
           U0: float = 2.0, U1: float = 2.0, samples: int = 20001) -> Track:
    """A midship track on a circle of radius R [m] from the execute at `origin` with heading
    psi0, turning `turns` full turns to `side`; speed U0 until `slow_after` rad of heading
    change, U1 after (time follows the speed; v = 0)."""
    theta = np.linspace(0.0, 2 * math.pi * turns, samples)
    speed = np.where(theta < slow_after, U0, U1)
    t = np.concatenate(([0.0], np.cumsum(R * np.diff(theta) / speed[1:])))
    along, across = R * np.sin(theta), side * R * (1.0 - np.cos(theta))
    c, s = math.cos(psi0), math.sin(psi0)
    x = origin[0] + along * c - across * s
    y = origin[1] + along * s + across * c
    return Track(t, x, y, psi0 + side * theta, speed, np.zeros_like(theta))


@pytest.mark.parametrize("side", [1.0, -1.0])
@pytest.mark.parametrize("psi0, origin", [(0.0, (0.0, 0.0)), (0.7, (12.0, -5.0))])
def test_turning_indices_of_a_circle(side, psi0, origin):
    R = 50.0
    track = circle(R, 2.0, side, psi0, origin)
    assert advance(track) == pytest.approx(R, rel=1e-6)        # quarter circle: R along
    assert transfer(track) == pytest.approx(R, rel=1e-6)       # and R across
    assert tactical_diameter(track) == pytest.approx(2 * R, rel=1e-6)
    assert steady_turning_diameter(track) == pytest.approx(2 * R, rel=1e-6)
    assert initial_turning_distance(track) == pytest.approx(R * 10 * DEG, rel=1e-6)  # arc to 10 deg
    assert speed_loss_ratio(track) == pytest.approx(0.0, abs=1e-12)


def test_speed_loss_and_steady_diameter_need_a_settled_turn():
    R, U0, U1 = 30.0, 2.0, 1.2
    track = circle(R, 2.0, slow_after=math.pi, U0=U0, U1=U1)  # slows down after half a turn
    assert speed_loss_ratio(track) == pytest.approx(1.0 - U1 / U0, rel=1e-9)
    short = circle(R, 0.9)  # 324 deg of heading change: no settled half turn yet
    assert math.isnan(steady_turning_diameter(short)) and math.isnan(speed_loss_ratio(short))
    assert tactical_diameter(short) == pytest.approx(2 * R, rel=1e-6)
    quarter = circle(R, 0.2)  # 72 deg: neither advance nor tactical diameter reached
    assert math.isnan(advance(quarter)) and math.isnan(tactical_diameter(quarter))


def test_turning_spec_indices_on_a_circle():
    track = circle(40.0, 1.5)
    found = maneuver_indices(TurningCircle(10.0), track)
    assert found.advance_m == pytest.approx(40.0, rel=1e-6)
    assert found.initial_turning_distance_m == pytest.approx(40.0 * 10 * DEG, rel=1e-6)  # 10 deg rudder: asked for
    assert math.isnan(found.first_overshoot_deg) and math.isnan(found.head_reach_m)
    assert math.isnan(maneuver_indices(TurningCircle(35.0), track).initial_turning_distance_m)


def sine_heading(first_deg: float, second_deg: float, period: float = 60.0, dt: float = 0.01):
    """(track, rudder): heading deviation first_deg sin(2 pi t / period) [deg] over the first
    half period and second_deg sin(...) over the second (then again first_deg ...); the
    rudder reverses where the heading reaches +-10 deg, as a 10/10 zig-zag's would."""
    t = np.arange(0.0, 1.6 * period, dt)
    phase = np.sin(2 * math.pi * t / period)
    amplitude = np.where((t % period) < period / 2, first_deg, second_deg)
    psi = amplitude * phase * DEG
    rudder = np.empty_like(t)
    side = 1.0
    for i, p in enumerate(psi):
        if side * p >= 10 * DEG:
            side = -side
        rudder[i] = side * 10 * DEG
    zeros = np.zeros_like(t)
    return Track(t, 2.0 * t, zeros, psi, zeros + 2.0, zeros), rudder


@pytest.mark.parametrize("first, second", [(15.0, 15.0), (17.5, 23.0)])
def test_overshoots_of_a_sine_heading(first, second):
    track, rudder = sine_heading(first, second)
    for given in (None, rudder):  # reversals from the heading alone, or from the rudder
        o1, o2 = zigzag_overshoots(track, 10.0, given)
        assert o1 == pytest.approx(first - 10.0, abs=1e-9)  # the peak lies on a sample
        assert o2 == pytest.approx(second - 10.0, abs=1e-9)


def test_overshoot_peak_between_samples_and_unfinished_runs():
    track, _ = sine_heading(15.0, 15.0, period=61.7, dt=0.37)  # peaks between samples
    o1, o2 = zigzag_overshoots(track, 10.0)
    assert o1 == pytest.approx(5.0, abs=2e-3) and o2 == pytest.approx(5.0, abs=2e-3)  # parabola through 3 samples
    half = Track(*(a[: int(0.2 / 1.6 * len(a))] for a in (track.t, track.x, track.y, track.psi, track.u, track.v)))
    assert all(math.isnan(o) for o in zigzag_overshoots(half, 10.0))  # past the check, before the peak: none yet
    found = maneuver_indices(ZigZag(10.0, 10.0), track)
    assert found.first_overshoot_deg == pytest.approx(5.0, abs=2e-3)
    assert found.initial_turning_distance_m > 0 and math.isnan(found.advance_m)


def test_head_and_track_reach_of_a_crash_stop():
    """u = U0 (1 - t / T) along the approach course: head reach U0 T / 2; the path bends
    sideways as y = a x^2, so the track reach is the parabola's arc length to the stop."""
    U0, T, a = 2.0, 40.0, 0.01
    t = np.linspace(0.0, 1.5 * T, 30001)
    u = U0 * (1.0 - t / T)
    along = U0 * (t - t * t / (2 * T))
    psi0 = 0.3
    lateral = a * along**2
    x = along * math.cos(psi0) - lateral * math.sin(psi0)
    y = along * math.sin(psi0) + lateral * math.cos(psi0)
    heading = np.full_like(t, psi0)
    heading[0] = psi0
    track = Track(t, x, y, heading, u, np.zeros_like(t))
    X = U0 * T / 2
    arc = (2 * a * X * math.sqrt(1 + (2 * a * X) ** 2) + math.asinh(2 * a * X)) / (4 * a)
    assert head_reach(track) == pytest.approx(X, rel=1e-7)
    assert track_reach(track) == pytest.approx(arc, rel=1e-6)
    found = maneuver_indices(CrashStop(), track)
    assert found.track_reach_m == pytest.approx(arc, rel=1e-6) and math.isnan(found.advance_m)
    running = Track(t, x, y, heading, u + 10.0, np.zeros_like(t))  # never stops
    assert math.isnan(head_reach(running)) and math.isnan(track_reach(running))


def test_imo_overshoot_limits_and_full_scale_L_over_U():
    assert overshoot_limits_10_10(5.0) == (10.0, 25.0)
    assert overshoot_limits_10_10(20.0) == (15.0, 32.5)   # 5 + 0.5 L/U, 17.5 + 0.75 L/U
    assert overshoot_limits_10_10(45.0) == (20.0, 40.0)
    assert full_scale_L_over_U(3.0, 0.3, 100.0) == pytest.approx(100.0)  # 10 s at model scale, sqrt(100) x
    assert full_scale_L_over_U(3.0, 0.3, None) is None


def test_criteria_met_or_not_in_ship_lengths():
    L = 10.0
    turn = maneuver_indices(TurningCircle(35.0), circle(22.0, 1.0))  # advance 2.2 L, tactical diameter 4.4 L
    verdicts = {c.index: c for c in criteria_for(TurningCircle(35.0), turn, L, 1.0, None)}
    assert verdicts["advance_m"].met and verdicts["advance_m"].ratio == pytest.approx(2.2, rel=1e-6)
    assert verdicts["tactical_diameter_m"].met and verdicts["tactical_diameter_m"].limit == 50.0
    wide = maneuver_indices(TurningCircle(35.0), circle(26.0, 1.0))  # tactical diameter 5.2 L
    assert not {c.index: c for c in criteria_for(TurningCircle(35.0), wide, L, 1.0, None)}["tactical_diameter_m"].met
    track, _ = sine_heading(17.5, 23.0)  # overshoots 7.5 and 13 deg
    zz = maneuver_indices(ZigZag(10.0, 10.0), track)
    unscaled = criteria_for(ZigZag(10.0, 10.0), zz, L, 1.0, None)
    assert [c.met for c in unscaled if c.index.endswith("_deg")] == [None, None]  # needs full-scale L/U
    scaled = {c.index: c for c in criteria_for(ZigZag(10.0, 10.0), zz, L, 2.0, 1.0)}  # L/U = 5 s: 10 and 25 deg
    assert scaled["first_overshoot_deg"].met and scaled["second_overshoot_deg"].met
    strict = {c.index: c for c in criteria_for(ZigZag(10.0, 10.0), zz, L, 1.0, 1.0)}  # L/U = 10 s: 10 and 25 deg
    assert strict["first_overshoot_deg"].limit == 10.0
