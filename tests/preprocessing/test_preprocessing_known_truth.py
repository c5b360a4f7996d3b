"""A known-truth probe of the whole pipeline, rendered without `preprocessing`'s own code.

The truth is closed-form kinematics on a 1 ms grid: a slow turn to starboard through north
(heading 346 deg -> 0 -> ...), a hard starboard turn at r = 0.16 rad/s (beyond the
FRT-DS-ESSO logs' 0.11), then one to port, each crossing 0/360 deg; u drops and v_m goes to
port (negative) in a starboard turn. The raw log is written here from first principles:
antennas off the centreline and not parallel to it, anemometers off midship, a gyro with
bias, a start 0.37 s after a whole second, time stamps jittered by up to 8 ms and dropped rows.
Outputs are compared at their own time stamps with the truth at those instants.
"""
from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from scipy.integrate import cumulative_trapezoid

from preprocessing import anemometer
from preprocessing.pipeline import Pipeline
from preprocessing.sensors import SensorLayout

FINE = 0.001   # s, step of the truth
START = 0.37   # s, first nominal stamp
DROPPED = (503, 1200, 1201, 1202, 1203, 1204)   # 10 Hz rows missing from the log
LAYOUT = SensorLayout(gnss_fore=(1.10, 0.12), gnss_aft=(-1.25, -0.04),
                      gnss_baseline=math.hypot(2.35, 0.16),
                      anemometer_1=(0.90, 0.15), anemometer_2=(-0.60, -0.20))
FOG_BIAS = math.radians(5.0) / 600   # rad/s, 5 deg per 10 min
ANEMO_DIR_NOISE = math.radians(2.0)  # rad
QUIET = dict(gnss=0.0, fog_noise=0.0, bias=0.0, anemo_speed=0.0, anemo_dir=0.0)


def _ramp(t, start, width):
    x = np.clip((t - start) / width, 0.0, 1.0)
    return 0.5 - 0.5 * np.cos(np.pi * x)


def _truth(duration: float = 205.0) -> dict[str, np.ndarray]:
    """Arrays on the 1 ms grid: t, u, v (midship, starboard +), r, psi (unwrapped), x (north),
    y (east), true wind speed UT and from-direction gT (from north towards east)."""
    t = np.arange(0.0, duration + FINE / 2, FINE)
    r = 0.01 + 0.15 * (_ramp(t, 50, 6) - _ramp(t, 95, 6)) - 0.12 * (_ramp(t, 120, 6) - _ramp(t, 170, 6))
    u = 0.55 - 4.0 * r ** 2
    v = -0.7 * r
    psi = -0.25 + cumulative_trapezoid(r, t, initial=0.0)
    x = 3.0 + cumulative_trapezoid(u * np.cos(psi) - v * np.sin(psi), t, initial=0.0)
    y = -7.0 + cumulative_trapezoid(u * np.sin(psi) + v * np.cos(psi), t, initial=0.0)
    ut = 3.0 + 0.3 * np.sin(2 * np.pi * t / 47)
    gt = np.radians(80 + 10 * np.sin(2 * np.pi * t / 73))
    return {"t": t, "u": u, "v": v, "r": r, "psi": psi, "x": x, "y": y, "UT": ut, "gT": gt}


def _apparent(tr, i, px, py):
    """Apparent wind (speed, from-direction from the bow towards starboard) at body point
    (px, py): true wind minus the point's velocity (u - r py, v + r px), in the body frame."""
    c, s = np.cos(tr["psi"][i]), np.sin(tr["psi"][i])
    wn, we = -tr["UT"][i] * np.cos(tr["gT"][i]), -tr["UT"][i] * np.sin(tr["gT"][i])  # blows towards
    wx, wy = wn * c + we * s, -wn * s + we * c
    ax, ay = wx - (tr["u"][i] - tr["r"][i] * py), wy - (tr["v"][i] + tr["r"][i] * px)
    return np.hypot(ax, ay), np.mod(np.arctan2(-ay, -ax), 2 * np.pi)


def _raw(tr, layout=LAYOUT, seed=0, jitter_ms=8, drop=DROPPED, gnss=0.015, fog_noise=0.002,
         bias=FOG_BIAS, anemo_speed=0.05, anemo_dir=ANEMO_DIR_NOISE, rows=2000,
         antenna_turn=0.0, rudder_unit="rad", start=START, outliers=()) -> pd.DataFrame:
    """The raw log; `outliers` : rows (of the written log) whose fore antenna is moved:
    even ones 30 cm along the baseline, odd ones turned 8 deg about the aft antenna."""
    rng = np.random.default_rng(seed)
    k = np.arange(rows)
    ms = np.rint((start + 0.1 * k) * 1000).astype(int) + rng.integers(-jitter_ms, jitter_ms + 1, rows)
    i = ms[~np.isin(k, drop)]                       # index into the 1 ms truth = stamp in ms
    n = len(i)
    c, s = np.cos(tr["psi"][i]), np.sin(tr["psi"][i])
    cols = {"t [s]": i * FINE}
    ca, sa = math.cos(antenna_turn), math.sin(antenna_turn)
    for name, (px, py) in (("fore", layout.gnss_fore), ("aft", layout.gnss_aft)):
        px, py = px * ca - py * sa, px * sa + py * ca   # the pair turned about midship
        cols[f"gnss_{name}_x [m]"] = tr["x"][i] + c * px - s * py + rng.normal(0, gnss, n)
        cols[f"gnss_{name}_y [m]"] = tr["y"][i] + s * px + c * py + rng.normal(0, gnss, n)
    for j, row in enumerate(outliers):
        ex = cols["gnss_fore_x [m]"][row] - cols["gnss_aft_x [m]"][row]
        ey = cols["gnss_fore_y [m]"][row] - cols["gnss_aft_y [m]"][row]
        if j % 2 == 0:
            scale = 1.0 + 0.30 / math.hypot(ex, ey)
            ex, ey = ex * scale, ey * scale
        else:
            ca, sa = math.cos(math.radians(8.0)), math.sin(math.radians(8.0))
            ex, ey = ex * ca - ey * sa, ex * sa + ey * ca
        cols["gnss_fore_x [m]"][row] = cols["gnss_aft_x [m]"][row] + ex
        cols["gnss_fore_y [m]"][row] = cols["gnss_aft_y [m]"][row] + ey
    cols["fog_yaw_rate [rad/s]"] = tr["r"][i] + bias + rng.normal(0, fog_noise, n)
    for j, (px, py) in ((1, layout.anemometer_1), (2, layout.anemometer_2)):
        speed, direction = _apparent(tr, i, px, py)
        cols[f"anemo_{j}_speed [m/s]"] = speed + rng.normal(0, anemo_speed, n)
        cols[f"anemo_{j}_dir [rad]"] = np.mod(direction + rng.normal(0, anemo_dir, n), 2 * np.pi)
    cols["n_prop [rps]"] = 10.0 + 2.0 * np.sin(tr["t"][i] / 9)
    rudder = np.radians(20) * np.sin(tr["t"][i] / 13)
    cols[f"delta_rudder [{rudder_unit}]"] = np.degrees(rudder) if rudder_unit == "deg" else rudder
    return pd.DataFrame(cols)


def _errors(seg: pd.DataFrame, tr, margin: float = 2.0) -> dict[str, float]:
    """RMS errors at the output's own time stamps, `margin` [s] from the segment's ends."""
    ts = seg["t"].to_numpy()
    keep = (ts >= ts[0] + margin) & (ts <= ts[-1] - margin)
    seg, i = seg[keep], np.rint(ts[keep] / FINE).astype(int)

    def rms(e):
        return float(np.sqrt(np.mean(np.square(e))))

    def ang(e):
        return np.mod(np.asarray(e) + np.pi, 2 * np.pi) - np.pi

    ua, ga = _apparent(tr, i, 0.0, 0.0)
    return {"psi_deg": math.degrees(rms(ang(seg["psi_hat"] - tr["psi"][i]))),
            "x": rms(seg["x_position_mid"] - tr["x"][i]), "y": rms(seg["y_position_mid"] - tr["y"][i]),
            "u": rms(seg["u_velo"] - tr["u"][i]), "v": rms(seg["vm_velo"] - tr["v"][i]),
            "r": rms(seg["r_angvelo"] - tr["r"][i]),
            "wind_true_speed": rms(seg["wind_velo_true"] - tr["UT"][i]),
            "wind_true_dir_deg": math.degrees(rms(ang(seg["wind_dir_true"] - tr["gT"][i]))),
            "wind_rel_speed": rms(seg["wind_velo_relative_mid"] - ua),
            "wind_rel_dir_deg": math.degrees(rms(ang(seg["wind_dir_relative_mid"] - ga))),
            "n_prop": float(np.max(np.abs(seg["n_prop"] - (10.0 + 2.0 * np.sin(tr["t"][i] / 9))))),
            "delta_rudder": float(np.max(np.abs(seg["delta_rudder"] - np.radians(20) * np.sin(tr["t"][i] / 13))))}


@pytest.fixture(scope="module")
def truth():
    return _truth()


def _check(errors: dict[str, float], bounds: dict[str, float]) -> None:
    for key, bound in bounds.items():
        assert errors[key] < bound, f"{key}: {errors[key]:.4g} >= {bound}"


def test_truth_crosses_north_and_turns_hard(truth):
    """The probe exercises what it claims: heading through 0/360 deg both ways, |r| 0.16."""
    wrapped = np.mod(truth["psi"], 2 * np.pi)
    crossings = np.flatnonzero(np.abs(np.diff(wrapped)) > np.pi)
    assert len(crossings) >= 3
    assert truth["r"].max() == pytest.approx(0.16) and truth["r"].min() == pytest.approx(-0.11)


def test_noise_free_log_gives_back_the_truth(truth):
    """Without sensor noise, only the 2-s central difference and the 0.2 Hz low-pass are left
    (during the 6-s ramps of r): heading, position and wind are exact, and the time stamps'
    jitter, the dropped rows and the 0.37 s start change nothing. Snapping the stamps to a
    grid anchored on the first one (+6 ms here) had shifted the output by 6 ms and left 3 mm
    of position and 0.03 deg of heading."""
    res = Pipeline(LAYOUT).run(_raw(truth, **QUIET), "probe")
    assert len(res.segments) == 1
    seg = res.segments[0]
    assert np.allclose(seg["t"], START + np.arange(len(seg)), atol=1e-9)   # t0, t0 + 1 s, ...
    assert seg["psi_hat"].between(-np.pi, np.pi).all()
    _check(_errors(seg, truth), {"psi_deg": 0.005, "x": 1e-4, "y": 1e-4, "u": 1e-3, "v": 1e-3,
                                 "r": 1e-3, "wind_true_speed": 2e-3, "wind_true_dir_deg": 0.02,
                                 "wind_rel_speed": 2e-4, "wind_rel_dir_deg": 0.005,
                                 "n_prop": 1.2e-3, "delta_rudder": 1e-4})   # linear over the 0.6-s dropout


def test_noisy_log_is_as_good_as_its_noise_allows(truth):
    """With 1.5 cm GNSS noise per antenna and axis, a drifting gyro (5 deg / 10 min, 0.002 rad/s
    white) and anemometers of 5 cm/s and 2 deg: position is the mean of two antennas (1.06 cm
    per axis, not smoothed), heading fuses gyro and the 0.52-deg two-antenna heading, u and v_m
    are smoothed differences, the wind is the mean of two sensors (3.5 cm/s, 1.4 deg) taken
    as it is. Measured over three seeds: psi 0.05-0.06 deg, x, y 1.0-1.1 cm, u, v_m 2.0-2.4
    mm/s, r 6.5e-4 rad/s, wind 3.4-3.8 cm/s and 1.3-1.6 deg."""
    for seed in (0, 1):
        res = Pipeline(LAYOUT).run(_raw(truth, seed=seed), "probe")
        assert len(res.segments) == 1
        seg = res.segments[0]
        errors = _errors(seg, truth)
        _check(errors, {"psi_deg": 0.1, "x": 0.013, "y": 0.013, "u": 3.5e-3, "v": 3.5e-3, "r": 1e-3,
                        "wind_true_speed": 0.045, "wind_true_dir_deg": 2.0,
                        "wind_rel_speed": 0.045, "wind_rel_dir_deg": 2.0})
        # v_m to port (< 0) in the starboard turn, to starboard in the port turn
        i = np.rint(seg["t"].to_numpy() / FINE).astype(int)
        hard = np.abs(truth["r"][i]) > 0.08
        assert np.all(np.sign(seg["vm_velo"][hard]) == -np.sign(truth["r"][i][hard]))
        # the gyro bias (1.45e-4 rad/s) within what its white noise allows: an angle random
        # walk of 0.002 sqrt(0.1) = 6.3e-4 rad/sqrt(s) leaves a 200-s slope 6.3e-4
        # sqrt(1.2 / 200) = 4.9e-5 rad/s uncertain (seed 1: 8.6e-5 off)
        assert abs(res.report.fog_bias_rad_s["mean"] - FOG_BIAS) < 1.2e-4


def test_first_sample_velocities_are_not_one_step_differences(truth):
    """A run's first 1 Hz sample is its first 10 Hz one, where the central difference is one
    step (0.1 s) wide: 20 times the noise of a 2-s one, and all differences of the first
    second share the first fix. Weighted as such in the Kalman/RTS pass, the first u, v_m
    over six 40-s logs are off by 1.5-2 cm/s RMS (the interior: 2 mm/s); weighted like the
    others, they were off by 6-8 cm/s (12 and 8 cm/s over 200-s logs)."""
    first = []
    for seed in range(6):
        seg = Pipeline(LAYOUT).run(_raw(truth, seed=seed, rows=400), "probe").segments[0]
        i = int(round(seg["t"].iloc[0] / FINE))
        first.append((seg["u_velo"].iloc[0] - truth["u"][i], seg["vm_velo"].iloc[0] - truth["v"][i]))
    rms_u, rms_v = np.sqrt(np.mean(np.square(first), axis=0))
    assert rms_u < 0.03 and rms_v < 0.03, (rms_u, rms_v)


def test_rejected_fixes_do_not_leak_into_their_neighbours(truth):
    """Outliers beside 1 Hz output samples (rows 10 k +- 1), in a jittered log: each is
    rejected (baseline or heading gate) before the fixes are moved to their grid times, so
    the output keeps the noise-free accuracy: 0.4 mm of position at worst (interpolating
    across them first put up to 8 % of an outlier into a neighbour that passed the checks:
    11.6 mm at 30.37 s)."""
    rows = (99, 301, 699, 901, 1399, 1601)
    res = Pipeline(LAYOUT).run(_raw(truth, outliers=rows, **QUIET), "probe")
    rejected = set(res.report.baseline.rejected_t) | set(res.report.heading_gate.rejected_t)
    assert len(rejected) == len(rows)
    seg = res.segments[0]
    _check(_errors(seg, truth), {"psi_deg": 0.005, "u": 1e-3, "v": 1e-3})
    i = np.rint(seg["t"].to_numpy() / FINE).astype(int)
    miss = np.hypot(seg["x_position_mid"] - truth["x"][i], seg["y_position_mid"] - truth["y"][i])
    assert miss.max() < 2e-3


def test_quality_report_of_the_time_defects(truth):
    """The report counts the dropped rows, gives the stamps' largest deviation from the grid
    (8 ms, measured from the median phase, not 14 ms from the first stamp's +6 ms) and one
    interpolated gap per channel at each dropout."""
    rep = Pipeline(LAYOUT).run(_raw(truth, **QUIET), "probe").report
    assert rep.rows == 2000 - len(DROPPED) and rep.missing_rows == len(DROPPED)
    assert 0.0075 < rep.time_jitter_max_s <= 0.0081
    fog = [(g.t_start, g.t_end, g.action) for g in rep.gaps if g.channel == "fog_yaw_rate"]
    assert fog == [(pytest.approx(50.67), pytest.approx(50.67), "interpolated"),
                   (pytest.approx(120.37), pytest.approx(120.77), "interpolated")]
    assert rep.gaps_split == 0 and rep.baseline.rejected == 0 and rep.heading_gate.rejected == 0


def test_a_log_starting_at_zero_with_a_late_first_stamp_starts_at_zero(truth):
    """First stamp 6 ms late (seed 0), the others spread about the grid: outputs at 0, 1, ... s
    (not 0.006, 1.006, ... s), the first written as 0.0, not -0.0."""
    raw = _raw(truth, start=0.0, **QUIET)
    assert raw["t [s]"].iloc[0] == pytest.approx(0.006)
    seg = Pipeline(LAYOUT).run(raw, "probe").segments[0]
    assert np.allclose(seg["t"], np.arange(len(seg)), atol=1e-9)
    assert seg["t"].iloc[0] == 0.0 and not np.signbit(seg["t"].iloc[0])


def test_heading_offset_turns_the_antenna_pair_about_midship(truth):
    """`heading_offset` (docs: Ship files, Sensors) is a turn of the listed antenna pair about
    midship beyond the listed positions, which already give the baseline's own direction
    (3.9 deg here, from the off-centre antennas)."""
    offset = math.radians(2.0)
    layout = SensorLayout(**{**LAYOUT.__dict__, "heading_offset": offset})
    raw = _raw(truth, layout=layout, antenna_turn=offset, **QUIET)
    _check(_errors(Pipeline(layout).run(raw, "probe").segments[0], truth),
           {"psi_deg": 0.005, "x": 1e-4, "y": 1e-4})
    # the same log read as if the listed positions were the whole story: 2 deg off
    wrong = _errors(Pipeline(LAYOUT).run(raw, "probe").segments[0], truth)
    assert wrong["psi_deg"] == pytest.approx(2.0, abs=0.01)


def test_rudder_in_degrees_and_revolutions_in_rpm_are_passed_through_in_si(truth):
    raw = _raw(truth, rudder_unit="deg", **QUIET)
    raw = raw.rename(columns={"n_prop [rps]": "n_prop [rpm]"}).assign(**{"n_prop [rpm]": raw["n_prop [rps]"] * 60})
    res = Pipeline(LAYOUT).run(raw, "probe")
    assert res.report.repairs == ["column n_prop: header unit [rpm], converted to [rps]",
                                  "column delta_rudder: header unit [deg], converted to [rad]"]
    _check(_errors(res.segments[0], truth), {"delta_rudder": 1e-4, "n_prop": 1.2e-3})


def test_apparent_wind_analytic_case():
    """Ship heading north at 5 m/s, true wind 10 m/s from the east: the air comes at
    (-5, -10) m/s in the body frame, 11.18 m/s from 63.43 deg to starboard; from the west it
    is 296.57 deg (63.43 deg to port). An anemometer 1 m forward and 0.5 m to starboard of
    midship while turning to starboard at 0.2 rad/s moves at (4.9, 0.2) m/s: it reads
    hypot(4.9, 10.2) m/s from atan2(10.2, 4.9) deg, and the true wind is recovered from it."""
    one = np.ones(1)
    for true_from, rel_deg in ((90.0, 63.434949), (270.0, 296.565051)):
        vx, vy = -10 * math.cos(math.radians(true_from)), -10 * math.sin(math.radians(true_from))
        speed, direction = anemometer.apparent_at(vx * one, vy * one, 5 * one, 0 * one, 0 * one, 0 * one,
                                                  (0.0, 0.0))
        assert speed[0] == pytest.approx(math.sqrt(125.0)) and math.degrees(direction[0]) == pytest.approx(rel_deg)
    sensor = (1.0, 0.5)
    speed, direction = anemometer.apparent_at(0 * one, -10 * one, 5 * one, 0 * one, 0.2 * one, 0 * one, sensor)
    assert speed[0] == pytest.approx(math.hypot(4.9, 10.2))
    assert math.degrees(direction[0]) == pytest.approx(math.degrees(math.atan2(10.2, 4.9)))
    ut, gt, ua, ga = anemometer.combine([(speed, direction)] * 2, 5 * one, 0 * one, 0.2 * one, 0 * one,
                                        [sensor, sensor])
    assert (ut[0], math.degrees(gt[0])) == pytest.approx((10.0, 90.0))
    assert (ua[0], math.degrees(ga[0])) == pytest.approx((math.sqrt(125.0), 63.434949))
