"""Processed u, v_m, r are not shifted in time against the truth (issue 12).

The identification bias of N'v and N'r through raw logs came from the velocity step
rotating the 2-s central difference (the mean earth velocity over [t - 1, t + 1] s) into the
body frame by the heading at t alone: while the yaw rate changes, v_m came out shifted by
u r' / 6 (a 0.06-0.07 s lag in a KVLCC2 zigzag). These tests use kinematic truths built
from closed-form u, v_m, r, a noise-free synthetic raw log and the full pipeline.
"""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from preprocessing import synth
from preprocessing.body_velocity import body_velocity
from preprocessing.pipeline import Pipeline
from preprocessing.sensors import SensorLayout

QUIET = synth.SynthSettings(gnss_noise=0.0, fog_drift=0.0, fog_noise=0.0,
                            anemo_speed_noise=0.0, anemo_dir_noise=0.0)


def _zigzag_like(period: float, duration: float = 200.0) -> pd.DataFrame:
    """10 Hz processed-schema truth: r = 0.06 sin(w t) rad/s, v_m = -0.06 sin(w t - 0.4)
    m/s (sway follows the yaw rate with the opposite sign, as in a zigzag), u = 1.1 m/s
    minus a slow 0.02 m/s speed loss, w = 2 pi / period."""
    t = np.round(np.arange(0.0, duration + 1e-9, 0.1), 6)
    w = 2 * np.pi / period
    zero = np.zeros_like(t)
    return pd.DataFrame({
        "t": t, "x_position_mid": zero, "u_velo": 1.1 - 0.02 * np.sin(w * t) ** 2,
        "y_position_mid": zero, "vm_velo": -0.06 * np.sin(w * t - 0.4), "psi_hat": zero,
        "r_angvelo": 0.06 * np.sin(w * t), "n_prop": zero + 10.0, "delta_rudder": zero,
        "wind_velo_relative_mid": zero, "wind_dir_relative_mid": zero,
        "wind_velo_true": zero, "wind_dir_true": zero})


def _lag_and_gain(estimate: np.ndarray, truth: np.ndarray, t: np.ndarray) -> tuple[float, float]:
    """Least squares of estimate - truth = -lag * d(truth)/dt + (gain - 1) * truth' + c
    (truth' = truth minus its mean): lag [s] > 0 when the estimate trails the truth."""
    rate = np.gradient(truth, t)
    design = np.c_[rate, truth - truth.mean(), np.ones_like(t)]
    c = np.linalg.lstsq(design, estimate - truth, rcond=None)[0]
    return float(-c[0]), float(1.0 + c[1])


@pytest.mark.parametrize("period", [20.0, 40.0])
def test_processed_velocities_and_yaw_rate_have_no_time_lag(period):
    layout = SensorLayout()
    res = synth.synthesise(_zigzag_like(period), layout, QUIET)
    seg = Pipeline(layout).run(res.raw, "zigzag_like").segments[0]
    truth = res.truth.iloc[::10].reset_index(drop=True)
    assert np.allclose(seg["t"], truth["t"].iloc[:len(seg)])
    inner = slice(5, len(seg) - 5)
    t = seg["t"].to_numpy()[inner]
    # v_m: before the fix it trailed by 0.17 s (rms error 2.2e-3 / 1.1e-3 m/s); now 0.003 s.
    # u: 0.03 s is left, the second-order r v_m' h^2 / 3 term of a turning difference
    # (1e-4 m/s here) against u's small 10-s variation, whose gain the 2-s window lowers to
    # 0.92 (period 20 s). r: the zero-phase low-pass.
    for column, max_lag, gain_tol, max_rms in (("vm_velo", 0.02, 0.03, 1e-3),
                                                ("u_velo", 0.05, 0.1, 1e-3),
                                                ("r_angvelo", 0.005, 0.01, 1e-4)):
        est, tru = seg[column].to_numpy()[inner], truth[column].to_numpy()[inner]
        lag, gain = _lag_and_gain(est, tru, t)
        assert abs(lag) < max_lag, f"{column}: lag {lag:+.3f} s"
        assert gain == pytest.approx(1.0, abs=gain_tol), f"{column}: gain {gain:.4f}"
        assert np.sqrt(np.mean((est - tru) ** 2)) < max_rms, column


def test_body_velocity_exact_in_a_steady_turn():
    """Constant u, v_m, r: the midship moves on a circle; the 2-s difference of its position
    is shorter than the arc and points along the mean heading of the window. Rotating by
    psi(t) would return (u, v_m) (1 - r^2 / 6): u 1.6e-3 m/s low here."""
    dt, u, v, r = 0.1, 1.2, -0.08, 0.09
    t = np.arange(0.0, 60.0, dt)
    psi = 0.3 + r * t
    # closed-form integral of R(psi) (u, v) from 0 to t
    ex = (u * (np.sin(psi) - np.sin(0.3)) + v * (np.cos(psi) - np.cos(0.3))) / r
    ey = (-u * (np.cos(psi) - np.cos(0.3)) + v * (np.sin(psi) - np.sin(0.3))) / r
    u_est, v_est = body_velocity(ex + 5.0, ey - 3.0, psi, dt, 1.0)
    inner = slice(10, -10)
    # what is left is the trapezoid rule on cos/sin of psi at 10 Hz: u r^2 dt^2 / 12 = 8e-6 m/s
    assert np.abs(u_est[inner] - u).max() < 2e-5
    assert np.abs(v_est[inner] - v).max() < 2e-5
