"""Kalman filtering with Rauch-Tung-Striebel smoothing (filterpy), forward then backward.

Two uses:

* `smooth_rate`: one velocity component (u or v_m) [m/s] from its central-difference
  estimate, state [value, its rate], white-jerk process noise `q`, measurement noise `r`.
* `fuse_heading`: heading from the FOG rate and the two-antenna heading. The state is
  [c, b], c = psi_fog - psi the accumulated gyro error [rad] and b the gyro bias [rad/s],
  c' = b; the measurement is psi_fog - psi_gnss. psi_fog (the trapezoid-integrated FOG
  rate) is known exactly, so psi = psi_fog - c. This keeps the model free of control
  inputs, which filterpy's RTS smoother does not take.
"""
from __future__ import annotations

import numpy as np
import pandas as pd
from filterpy.kalman import KalmanFilter


def _cv_filter(dt: float, q: float, r: float, x0: float, p0_rate: float) -> KalmanFilter:
    """Constant-rate model x = [value, rate], white noise of the rate's derivative (PSD q)."""
    kf = KalmanFilter(dim_x=2, dim_z=1)
    kf.F = np.array([[1.0, dt], [0.0, 1.0]])
    kf.H = np.array([[1.0, 0.0]])
    kf.Q = q * np.array([[dt ** 3 / 3, dt ** 2 / 2], [dt ** 2 / 2, dt]])
    kf.R = np.array([[r]])
    kf.x = np.array([[x0], [0.0]])
    kf.P = np.diag([r, p0_rate])
    return kf


def _inv_1x1(s: np.ndarray) -> np.ndarray:
    """Inverse of the 1x1 innovation covariance (a cheap stand-in for np.linalg.inv)."""
    return 1.0 / s


def _inv_2x2(p: np.ndarray) -> np.ndarray:
    """Closed-form inverse of a 2x2 covariance (the RTS pass inverts one per step)."""
    a, b, c, d = p[0, 0], p[0, 1], p[1, 0], p[1, 1]
    return np.array([[d, -b], [-c, a]]) / (a * d - b * c)


def _run(kf: KalmanFilter, z: np.ndarray, r: np.ndarray | None = None
         ) -> tuple[np.ndarray, np.ndarray]:
    """Forward filter + RTS pass; NaN measurements are skipped (predict only). `r`: each
    measurement's variance (shape (N,)), else `kf.R` for all."""
    zs = [None if np.isnan(v) else np.array([[v]]) for v in z]
    kf.inv = _inv_1x1                    # dim_z = 1: S is 1x1
    rs = None if r is None else [np.array([[v]]) for v in r]
    means, covs, _, _ = kf.batch_filter(zs, Rs=rs)
    xs, ps, _, _ = kf.rts_smoother(means, covs, inv=_inv_2x2)
    return xs[:, :, 0], ps


def smooth_rate(z: np.ndarray, dt: float, q: float, r: float,
                r_scale: np.ndarray | None = None) -> np.ndarray:
    """Smoothed value of a noisy signal `z` (shape (N,), step dt [s]), same units as z.

    q : PSD of the white process noise driving the value's second derivative [unit^2/s^5].
    r : variance of z's noise [unit^2]; r_scale : each sample's variance relative to r
    (shape (N,); `differencing.noise_scale` for the narrower differences at the ends).
    """
    z = np.asarray(z, float)
    first = int(np.flatnonzero(np.isfinite(z))[0])
    r0 = r if r_scale is None else r * float(r_scale[first])
    xs, _ = _run(_cv_filter(dt, q, r0, z[first], 1.0), z, None if r_scale is None else r * np.asarray(r_scale))
    return xs[:, 0]


def gate_heading(psi_fog: np.ndarray, psi_gnss: np.ndarray, dt: float, window: float,
                 k_sigma: float, floor: float) -> tuple[np.ndarray, np.ndarray, float]:
    """Measurement z = psi_fog - psi_gnss (unwrapped) and the GNSS samples to keep.

    A sample is rejected when z departs from its running median (window [s]) by more than
    max(k_sigma * robust sigma, floor) [rad]: the gyro is smooth over a few seconds, so a
    jump there is a GNSS antenna outlier. Returns (z with NaN where rejected or missing,
    keep mask, robust sigma [rad]).
    """
    z = np.full(len(psi_gnss), np.nan)
    ok = np.isfinite(psi_gnss)
    if ok.sum() < 3:
        return z, ok, float("nan")
    z[ok] = np.unwrap(psi_fog[ok] - psi_gnss[ok])
    w = max(3, int(round(window / dt)) | 1)
    med = pd.Series(z).rolling(w, center=True, min_periods=3).median().to_numpy()
    resid = z - med
    sigma = 1.4826 * float(np.nanmedian(np.abs(resid)))
    with np.errstate(invalid="ignore"):
        keep = ok & (np.abs(resid) <= max(k_sigma * sigma, floor))
    z[~keep] = np.nan
    return z, keep, sigma


def fuse_heading(psi_fog: np.ndarray, z: np.ndarray, dt: float, fog_noise: float,
                 bias_walk: float, heading_noise: float) -> tuple[np.ndarray, np.ndarray]:
    """Smoothed heading [rad] (unwrapped) and gyro bias [rad/s], each shape (N,).

    psi_fog : integrated FOG rate [rad]; z : psi_fog - psi_gnss [rad], NaN where no GNSS.
    fog_noise : white FOG noise [rad/s] per sample; bias_walk : bias random walk
    [rad/s/sqrt(s)]; heading_noise : two-antenna heading noise [rad].
    """
    kf = KalmanFilter(dim_x=2, dim_z=1)
    kf.F = np.array([[1.0, dt], [0.0, 1.0]])
    kf.H = np.array([[1.0, 0.0]])
    kf.Q = np.diag([(fog_noise * dt) ** 2, bias_walk ** 2 * dt])
    kf.R = np.array([[heading_noise ** 2]])
    kf.x = np.array([[z[np.isfinite(z)][0]], [0.0]])
    kf.P = np.diag([heading_noise ** 2, 1e-6])
    xs, _ = _run(kf, z)
    return psi_fog - xs[:, 0], xs[:, 1]
