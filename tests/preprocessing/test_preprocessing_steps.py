"""Single steps of `preprocessing/` against closed-form expectations."""
from __future__ import annotations

import json
import os

import numpy as np
import pandas as pd
import pytest

from preprocessing.quality import QualityReport

from preprocessing import anemometer, differencing, geodesy, gnss, gyro, resample, writer
from preprocessing.frames import body_to_earth, earth_to_body, flow_velocity, from_direction
from preprocessing.sensors import SensorLayout


def test_geodesy_round_trip_and_axes():
    north = np.array([0.0, 100.0, -250.0, 800.0])
    east = np.array([0.0, -50.0, 300.0, 20.0])
    lat, lon = geodesy.local_to_latlon(north, east, 34.8, 135.5)
    n2, e2 = geodesy.latlon_to_local(lat, lon, 34.8, 135.5)
    assert np.abs(n2 - north).max() < 1e-4 and np.abs(e2 - east).max() < 1e-4
    assert lat[1] > 34.8 and lon[1] < 135.5          # north is +lat, west is -lon
    # 1e-5 deg of latitude is about 1.11 m at 35 deg
    n, _ = geodesy.latlon_to_local(np.array([34.80001]), np.array([135.5]), 34.8, 135.5)
    assert n[0] == pytest.approx(1.109, abs=0.002)


def test_central_difference_exact_on_quadratic():
    t = np.arange(0, 30, 0.1)
    p = 0.3 * t ** 2 - 2 * t + 1
    v = differencing.central_difference(p, 0.1, 1.0)
    assert np.allclose(v[10:-10], 0.6 * t[10:-10] - 2, atol=1e-9)
    assert np.allclose(v[1:-1], 0.6 * t[1:-1] - 2, atol=1e-9)   # shrunk half-width at ends


def test_noise_scale_of_the_narrower_differences_at_the_ends():
    """A difference over m steps has a noise std proportional to 1 / m: at 10 Hz and 1.0 s the
    full width is 20 steps, the one-sided ends 1 step (variance x 400), sample 3 six steps."""
    scale = differencing.noise_scale(50, 0.1, 1.0)
    assert scale[0] == pytest.approx(400.0) and scale[-1] == pytest.approx(400.0)
    assert scale[3] == pytest.approx((20 / 6) ** 2) and scale[-4] == pytest.approx((20 / 6) ** 2)
    assert np.all(scale[10:-10] == 1.0)


def test_lowpass_minus_3db_at_cutoff_and_zero_phase():
    fs, t = 10.0, np.arange(0, 600, 0.1)
    for f, gain in ((0.2, 2 ** -0.5), (0.02, 1.0)):
        x = np.sin(2 * np.pi * f * t)
        y = gyro.lowpass(x, fs, 0.2, 2)
        mid = slice(1000, -1000)
        assert np.sqrt(2 * np.mean(y[mid] ** 2)) == pytest.approx(gain, abs=0.01)
        lag = np.argmax(np.correlate(y[mid], x[mid], "full")) - (len(x[mid]) - 1)
        assert lag == 0


def test_rotations_inverse_and_sign():
    ex, ey = body_to_earth(np.pi / 2, 1.0, 0.0)       # bow east
    assert ex == pytest.approx(0.0, abs=1e-12) and ey == pytest.approx(1.0)
    ex, ey = body_to_earth(np.pi / 2, 0.0, 1.0)       # starboard south
    assert ex == pytest.approx(-1.0) and ey == pytest.approx(0.0, abs=1e-12)
    bx, by = earth_to_body(0.7, *body_to_earth(0.7, 0.3, -0.2))
    assert (bx, by) == pytest.approx((0.3, -0.2))


def test_wind_from_direction_and_sensor_round_trip():
    vx, vy = flow_velocity(2.0, 0.0)                  # from the north blows south
    assert vx == pytest.approx(-2.0)
    speed, direction = from_direction(vx, vy)
    assert speed == pytest.approx(2.0) and direction == pytest.approx(0.0)
    n = 5
    u, v, r, psi = np.full(n, 0.5), np.full(n, 0.05), np.full(n, 0.1), np.linspace(0, 3, n)
    tvx, tvy = flow_velocity(np.full(n, 3.0), np.full(n, 1.0))
    pos = [(0.9, 0.1), (-0.6, -0.2)]
    sensors = [anemometer.apparent_at(tvx, tvy, u, v, r, psi, p) for p in pos]
    ut, gt, ua, ga = anemometer.combine(sensors, u, v, r, psi, pos)
    assert np.allclose(ut, 3.0) and np.allclose(gt, 1.0)
    ua2, ga2 = anemometer.apparent_at(tvx, tvy, u, v, r, psi, (0.0, 0.0))
    assert np.allclose(ua, ua2) and np.allclose(ga, ga2)


def test_baseline_heading_midship():
    lay = SensorLayout()
    psi = np.array([0.0, 1.0, -2.5])
    x, y = np.array([1.0, 2.0, 3.0]), np.array([0.0, -1.0, 5.0])
    fx, fy = body_to_earth(psi, *lay.gnss_fore)
    ax, ay = body_to_earth(psi, *lay.gnss_aft)
    fx, fy, ax, ay = fx + x, fy + y, ax + x, ay + y
    assert np.allclose(gnss.baseline_error(fx, fy, ax, ay, lay), 0.0)
    assert np.allclose(gnss.antenna_heading(fx, fy, ax, ay, lay), psi)
    mx, my = gnss.midship_position(fx, fy, ax, ay, psi, lay)
    assert np.allclose(mx, x) and np.allclose(my, y)
    assert list(gnss.baseline_ok(np.array([0.049, -0.05, np.nan]), 0.05)) == [True, False, False]


def test_resample_takes_samples_on_the_run_grid():
    idx = np.arange(37, 80)
    i = resample.sample_indices(idx, 10)
    assert list(idx[i]) == [40, 50, 60, 70]


def test_writer_is_atomic_and_complete(tmp_path):
    seg = pd.DataFrame({c: [0.0, 1.0] for c in writer.schema.PROCESSED})
    paths = writer.write_segments(tmp_path, "run", [seg, seg], QualityReport("x"))
    assert sorted(p.name for p in paths) == ["run.report.json", "run_seg1.csv", "run_seg2.csv"]
    assert json.loads((tmp_path / "run.report.json").read_text())["outputs"] == ["run_seg1.csv", "run_seg2.csv"]
    assert not [f for f in os.listdir(tmp_path) if f.endswith(".tmp")]
    with pytest.raises(KeyError):
        writer.write_segments(tmp_path / "bad", "run", [seg.drop(columns=["t"])], QualityReport("bad"))
    assert list((tmp_path / "bad").iterdir()) == []


def test_quality_report_round_trips_through_json():
    report = QualityReport.from_dict({
        "file": "run.csv", "rows": 1200, "repairs": ["x"], "gaps": [
            {"channel": "gnss", "t_start": 1.0, "t_end": 2.5, "duration_s": 1.5, "action": "split"}],
        "baseline": {"rejected": 2, "rejected_t": [3.0, 4.0], "error_mean_m": 0.01},
        "segments": [{"t_start": 0.0, "t_end": 60.0, "samples": 61}, {"t_start": 70.0, "t_end": 100.0, "samples": 31}]})
    assert report.kept_s == 90.0 and report.baseline.rejected == 2 and report.gaps[0].action == "split"
    again = QualityReport.from_json(report.to_json())
    assert again == report
    assert json.loads(report.to_json())["baseline"] == {"rejected": 2, "rejected_t": [3.0, 4.0], "error_mean_m": 0.01}
