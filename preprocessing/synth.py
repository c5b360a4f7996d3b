"""Raw 10 Hz logs with known truth, synthesised from a processed run.

The public processed files are not kinematically self-consistent (their u, v_m, r differ
from the derivatives of their own x, y, psi), so the truth is built from the run's t, u, v_m,
r, actuators and true wind: psi is integrated from r (trapezoid, starting at the file's first
psi) and the midship position from (u, v_m) rotated by psi (starting at the file's first
position); the relative wind is recomputed. Sensors are then placed by a `SensorLayout`
and seeded noise is added.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from scipy.integrate import cumulative_trapezoid
from scipy.signal import lfilter

from preprocessing import anemometer, geodesy, gnss, schema
from preprocessing.frames import body_to_earth, flow_velocity, wrap_pi, wrap_2pi
from preprocessing.sensors import SensorLayout


@dataclass(frozen=True)
class SynthSettings:
    """Noise and defects of a synthetic raw log (all seeded by `seed`).

    gnss_noise : white noise per antenna and axis [m]; gnss_correlated : std [m] of an
    extra first-order Gauss-Markov component with time constant `gnss_tau` [s].
    outliers : number of injected antenna outliers (half change the baseline length by
    10-40 cm, half rotate the fore antenna about the aft one by 4-15 deg, keeping length).
    dropouts : ((start [s], duration [s]), ...) GNSS outages; `dropout_rows` drops whole
    rows instead of emptying the GNSS cells.
    fog_drift : mean gyro bias [rad/s] (5 deg per 10 min); fog_noise : white [rad/s].
    anemo_speed_noise [m/s], anemo_dir_noise [rad].
    latlon : write WGS-84 fixes around `reference` (lat, lon) [deg] instead of x/y.
    """

    seed: int = 0
    gnss_noise: float = 0.015
    gnss_correlated: float = 0.0
    gnss_tau: float = 10.0
    outliers: int = 0
    dropouts: tuple[tuple[float, float], ...] = ()
    dropout_rows: bool = False
    fog_drift: float = np.radians(5.0) / 600.0
    fog_noise: float = 0.002
    anemo_speed_noise: float = 0.05
    anemo_dir_noise: float = np.radians(2.0)
    latlon: bool = False
    reference: tuple[float, float] = (34.8195, 135.5236)


OUTLIER_MARGIN = 30  # rows at either end of a log that get no outlier


@dataclass
class SynthResult:
    """raw : raw log (header ``name [unit]``); truth : processed-schema truth at 10 Hz
    (bare names); outliers : [{'row', 't', 'kind'}]; dropouts : [(t_start, t_end)] [s]."""

    raw: pd.DataFrame
    truth: pd.DataFrame
    outliers: list[dict] = field(default_factory=list)
    dropouts: list[tuple[float, float]] = field(default_factory=list)


def read_processed(path) -> pd.DataFrame:
    """A processed-schema CSV with bare column names (`processed_run`)."""
    return processed_run(pd.read_csv(path), path)


def processed_run(df: pd.DataFrame, path) -> pd.DataFrame:
    """A processed run read from `path` with bare column names, checked: every channel
    present, every cell a finite number, time strictly increasing (`schema.RawLogError`
    naming the file, column and row otherwise). All-empty rows are dropped."""
    df = df.copy()
    df.columns = [str(c).split(" [")[0].strip() for c in df.columns]
    missing = [c for c in schema.PROCESSED if c not in df.columns]
    if missing:
        raise schema.RawLogError(f"{path}: column {missing[0]}: missing from processed run")
    kept = df.dropna(how="all")
    rows = kept.index.to_numpy() + 2   # each kept row's line of the file (the header is line 1)
    df = kept.reset_index(drop=True)
    if len(df) < 2:
        raise schema.RawLogError(f"{path}: fewer than two data rows")
    used = [c for c in schema.PROCESSED if "relative" not in c]   # the relative wind is recomputed
    values = df[used].apply(pd.to_numeric, errors="coerce").to_numpy(dtype=float)
    bad = ~np.isfinite(values)
    if bad.any():
        row, col = np.argwhere(bad)[0]
        raise schema.RawLogError(f"{path}: column {used[col]} is empty, NaN or not a number at "
                                 f"line {rows[row]} ({int(bad.any(axis=1).sum())} bad rows); a truth is built "
                                 "from complete rows only: fill or cut them")
    t = values[:, used.index("t")]
    step = np.diff(t)
    if (step <= 0).any():
        k = int(np.argmax(step <= 0)) + 1
        raise schema.RawLogError(f"{path}: column t is not strictly increasing at line {rows[k]} "
                                 f"(t = {t[k]:g} s after {t[k - 1]:g} s): remove the repeated or earlier time")
    df[used] = values
    return df


def truth_from_processed(run: pd.DataFrame) -> pd.DataFrame:
    """Kinematically consistent truth (processed schema, bare names) from a processed run."""
    t = run["t"].to_numpy(float)
    u, v, r = (run[c].to_numpy(float) for c in ("u_velo", "vm_velo", "r_angvelo"))
    psi = run["psi_hat"].iloc[0] + cumulative_trapezoid(r, t, initial=0.0)
    ex, ey = body_to_earth(psi, u, v)
    x = run["x_position_mid"].iloc[0] + cumulative_trapezoid(ex, t, initial=0.0)
    y = run["y_position_mid"].iloc[0] + cumulative_trapezoid(ey, t, initial=0.0)
    ut, gt = run["wind_velo_true"].to_numpy(float), run["wind_dir_true"].to_numpy(float)
    ua, ga = anemometer.apparent_at(*flow_velocity(ut, gt), u, v, r, psi, (0.0, 0.0))  # type: ignore[call-arg]
    out = pd.DataFrame({
        "t": t, "x_position_mid": x, "u_velo": u, "y_position_mid": y, "vm_velo": v,
        "psi_hat": wrap_pi(psi), "r_angvelo": r, "n_prop": run["n_prop"].to_numpy(float),
        "delta_rudder": run["delta_rudder"].to_numpy(float),
        "wind_velo_relative_mid": ua, "wind_dir_relative_mid": ga,
        "wind_velo_true": ut, "wind_dir_true": wrap_2pi(gt)})
    return out


def _gauss_markov(rng, n: int, dt: float, sigma: float, tau: float) -> np.ndarray:
    """First-order Gauss-Markov noise, stationary std `sigma`, time constant `tau` [s]."""
    if sigma <= 0:
        return np.zeros(n)
    a = np.exp(-dt / tau)
    e = rng.normal(0.0, sigma * np.sqrt(1 - a * a), n)
    e[0] = rng.normal(0.0, sigma)
    return lfilter([1.0], [1.0, -a], e)


def synthesise(run: pd.DataFrame, layout: SensorLayout, settings: SynthSettings = SynthSettings()
               ) -> SynthResult:
    """Raw 10 Hz log and truth from a processed run (bare-name DataFrame, 10 Hz)."""
    rng = np.random.default_rng(settings.seed)
    truth = truth_from_processed(run)
    t = truth["t"].to_numpy()
    n = len(t)
    dt = float(np.median(np.diff(t)))
    psi = run["psi_hat"].iloc[0] + cumulative_trapezoid(truth["r_angvelo"].to_numpy(), t, initial=0.0)
    x, y = truth["x_position_mid"].to_numpy(), truth["y_position_mid"].to_numpy()
    u, v, r = (truth[c].to_numpy() for c in ("u_velo", "vm_velo", "r_angvelo"))

    ant = {}
    for name, pos in zip(("fore", "aft"), gnss.antenna_positions(layout)):
        ox, oy = body_to_earth(psi, *pos)
        for axis, base in (("x", x + ox), ("y", y + oy)):
            noise = rng.normal(0.0, settings.gnss_noise, n) + _gauss_markov(
                rng, n, dt, settings.gnss_correlated, settings.gnss_tau)
            ant[f"{name}_{axis}"] = base + noise

    outliers: list[dict] = []
    if settings.outliers:
        rows = np.sort(rng.choice(np.arange(OUTLIER_MARGIN, n - OUTLIER_MARGIN), settings.outliers, replace=False))
        for i, row in enumerate(rows):
            dfx = ant["fore_x"][row] - ant["aft_x"][row]
            dfy = ant["fore_y"][row] - ant["aft_y"][row]
            if i % 2 == 0:   # length change along the baseline
                scale = 1.0 + rng.choice([-1, 1]) * rng.uniform(0.10, 0.40) / layout.gnss_baseline
                nx, ny, kind = dfx * scale, dfy * scale, "baseline_length"
            else:            # rotation about the aft antenna, length kept
                a = rng.choice([-1, 1]) * np.radians(rng.uniform(4.0, 15.0))
                nx = dfx * np.cos(a) - dfy * np.sin(a)
                ny = dfx * np.sin(a) + dfy * np.cos(a)
                kind = "rotation"
            ant["fore_x"][row] = ant["aft_x"][row] + nx
            ant["fore_y"][row] = ant["aft_y"][row] + ny
            outliers.append({"row": int(row), "t": float(t[row]), "kind": kind})

    phase = rng.uniform(0, 2 * np.pi)
    bias = rng.choice([-1, 1]) * settings.fog_drift * (1.0 + 0.3 * np.sin(2 * np.pi * t / 1200.0 + phase))
    fog = r + bias + rng.normal(0.0, settings.fog_noise, n)

    ut, gt = truth["wind_velo_true"].to_numpy(), truth["wind_dir_true"].to_numpy()
    wvx, wvy = flow_velocity(ut, gt)
    anemo = {}
    for k, pos in ((1, layout.anemometer_1), (2, layout.anemometer_2)):
        sp, di = anemometer.apparent_at(wvx, wvy, u, v, r, psi, pos)
        anemo[f"anemo_{k}_speed"] = np.maximum(sp + rng.normal(0, settings.anemo_speed_noise, n), 0.0)
        anemo[f"anemo_{k}_dir"] = wrap_2pi(di + rng.normal(0, settings.anemo_dir_noise, n))

    cols: dict[str, np.ndarray] = {"t": t}
    if settings.latlon:
        lat0, lon0 = settings.reference
        for name in ("fore", "aft"):
            la, lo = geodesy.local_to_latlon(ant[f"{name}_x"], ant[f"{name}_y"], lat0, lon0)
            cols[f"gnss_{name}_lat"], cols[f"gnss_{name}_lon"] = la, lo
        gnss_cols = [c for c in cols if c.startswith("gnss_")]
    else:
        for k, val in ant.items():  # type: ignore[assignment]
            cols[f"gnss_{k}"] = val
        gnss_cols = [f"gnss_{k}" for k in ant]
    cols["fog_yaw_rate"] = fog
    cols.update(anemo)
    cols["n_prop"] = truth["n_prop"].to_numpy()
    cols["delta_rudder"] = truth["delta_rudder"].to_numpy()
    raw = pd.DataFrame(cols)

    drops: list[tuple[float, float]] = []
    remove = np.zeros(n, bool)
    for start, duration in settings.dropouts:
        t0 = t[0] + start
        mask = (t >= t0 - 1e-6) & (t < t0 + duration - 1e-6)
        if mask.any():
            drops.append((float(t[mask][0]), float(t[mask][-1])))
        if settings.dropout_rows:
            remove |= mask
        else:
            raw.loc[mask, gnss_cols] = np.nan
    raw = raw.loc[~remove].reset_index(drop=True)
    units = {**schema.RAW_COMMON, **schema.RAW_LOCAL, **schema.RAW_LATLON}
    raw.columns = [f"{c} [{units[c]}]" for c in raw.columns]
    return SynthResult(raw, truth, outliers, drops)


def score(segments: list[pd.DataFrame], truth: pd.DataFrame, dropouts=(), margin: float = 2.0,
          min_wind: float = 0.5) -> dict:
    """RMS errors of processed segments against the truth at their (1 Hz) sample times.

    Samples within `margin` [s] of a segment's ends or of a dropout (t_start, t_end) are
    left out; wind directions only where that wind's true speed >= `min_wind` [m/s].
    Returns {'psi_deg', 'u', 'v', 'r', 'x', 'y', 'pos', 'wind_speed', 'wind_dir_deg',
    'wind_rel_speed', 'wind_rel_dir_deg', 'samples'} (SI units unless named).
    """
    tt = np.round(truth["t"].to_numpy(), 6)
    parts = []
    for seg in segments:
        ts = seg["t"].to_numpy()
        ok = (ts >= ts[0] + margin) & (ts <= ts[-1] - margin)
        for a, b in dropouts:
            ok &= (ts < a - margin) | (ts > b + margin)
        parts.append(seg.loc[ok])
    est = pd.concat(parts, ignore_index=True)
    idx = np.searchsorted(tt, np.round(est["t"].to_numpy(), 6))
    tru = truth.iloc[idx].reset_index(drop=True)

    def rms(e):
        return float(np.sqrt(np.mean(np.square(e)))) if len(e) else float("nan")

    out = {"samples": len(est)}
    out["psi_deg"] = np.degrees(rms(wrap_pi(est["psi_hat"] - tru["psi_hat"])))
    for key, col in (("u", "u_velo"), ("v", "vm_velo"), ("r", "r_angvelo"),
                     ("x", "x_position_mid"), ("y", "y_position_mid"),
                     ("wind_speed", "wind_velo_true"), ("wind_rel_speed", "wind_velo_relative_mid")):
        out[key] = rms(est[col] - tru[col])
    out["pos"] = float(np.hypot(out["x"], out["y"]))  # type: ignore[assignment]
    for key, sp, col in (("wind_dir_deg", "wind_velo_true", "wind_dir_true"),
                         ("wind_rel_dir_deg", "wind_velo_relative_mid", "wind_dir_relative_mid")):
        m = tru[sp].to_numpy() >= min_wind
        out[key] = np.degrees(rms(wrap_pi(est[col].to_numpy()[m] - tru[col].to_numpy()[m])))
    return out
