"""The preprocessing pipeline: raw 10 Hz log -> processed 1 Hz segments + quality report.

Steps, in the order of the docs' input formats page: (1) read, validate, put on the 10 Hz grid, find gaps;
(2) lat/lon -> local; (3) baseline check; (4) heading (FOG + two-antenna fusion, with
gating); (5) midship position; (6) central difference; (7) Kalman/RTS on u, v_m;
(8) FOG low-pass; (9) wind; (10) take samples at the output rate; (11) write (`writer`).

Gaps: samples missing (absent rows, empty cells, rejected GNSS fixes) over at most
`max_interp_gap` seconds are linearly interpolated; a longer gap splits the run into
segments, each processed on its own; segments shorter than `min_segment` are dropped.
Every such decision goes into the report. Samples are put on the nominal 0.1 s grid whose
phase is the median of the time stamps', each column's values linearly interpolated from
their stamps to the grid times, the GNSS fixes after the baseline check and the heading gate
from the kept ones (the largest deviation is reported; more than 25 ms is an error).
"""
from __future__ import annotations

import os
from dataclasses import asdict, dataclass

import numpy as np
import pandas as pd
from scipy.integrate import cumulative_trapezoid

from preprocessing.quality import QualityReport
from preprocessing import (anemometer, body_velocity, differencing, geodesy, gnss, gyro, resample, schema,
                           smoothing)
from preprocessing.frames import wrap_pi
from preprocessing.schema import RawLogError
from preprocessing.sensors import SensorLayout


@dataclass(frozen=True)
class PreprocessSettings:
    """Pipeline settings; defaults follow the paper (section 4.1).

    diff_dt : half-width of the central difference [s] (paper: 1.0).
    velocity_q : PSD of the white jerk driving the velocity model [m^2/s^5];
    velocity_r : variance of a central-difference velocity [m^2/s^2]. Together they set
    the Kalman/RTS bandwidth on u and v_m.
    gnss_noise : per-antenna GNSS noise [m], gives the two-antenna heading noise.
    fog_noise : white FOG noise [rad/s]; fog_bias_walk : bias random walk [rad/s/sqrt(s)].
    gate_sigma, gate_floor [rad], gate_window [s] : a GNSS heading is rejected when it
    departs from the gyro-propagated one by more than max(gate_sigma * robust std, floor).
    cutoff [Hz], lowpass_order : the zero-phase Butterworth on the FOG (paper: 0.2 Hz).
    baseline_tolerance [m] : GNSS samples whose baseline is off by this much are rejected.
    min_baseline_pass : the run fails when fewer than this share of fixes pass (wrong
    baseline in the ship definition, or a broken antenna).
    max_interp_gap [s] : longer gaps split the run; min_segment [s] : shorter segments are
    dropped. output_rate [Hz] : samples taken at t0, t0 + 1/rate, ...
    reference : (lat, lon) [deg] of the local origin for lat/lon logs; None = first aft fix.
    swapped_antennas : "error" or "repair" when fore/aft look swapped (heading 180 deg off
    the course while moving ahead).
    accepted_fix : GGA quality values kept when the log has ``gnss_*_fix`` columns (4 = RTK
    fixed / CLAS); other fixes are rejected like baseline failures (empty = unknown, kept).
    """

    diff_dt: float = 1.0
    velocity_q: float = 1e-4
    velocity_r: float = 3e-5
    gnss_noise: float = 0.015
    fog_noise: float = 0.002
    fog_bias_walk: float = 1e-5
    gate_sigma: float = 5.0
    gate_floor: float = np.radians(1.5)
    gate_window: float = 10.0
    cutoff: float = 0.2
    lowpass_order: int = 2
    baseline_tolerance: float = 0.05
    min_baseline_pass: float = 0.5
    max_interp_gap: float = 1.0
    min_segment: float = 10.0
    output_rate: float = 1.0
    reference: tuple[float, float] | None = None
    swapped_antennas: str = "error"
    accepted_fix: tuple[int, ...] = (4,)

    def __post_init__(self) -> None:
        if self.swapped_antennas not in ("error", "repair"):
            raise ValueError("swapped_antennas must be 'error' or 'repair'")
        if not (self.output_rate > 0 and np.isfinite(self.output_rate)):
            raise ValueError(f"output_rate {self.output_rate} Hz: must be > 0 (and divide 10 Hz)")
        step = schema.NOMINAL_DT * round(1.0 / (self.output_rate * schema.NOMINAL_DT))
        if step == 0 or abs(1.0 / self.output_rate - step) > 1e-9:
            raise ValueError(f"output_rate {self.output_rate} Hz: must divide 10 Hz")
        if not (self.max_interp_gap >= 0 and np.isfinite(self.max_interp_gap)):
            raise ValueError(f"max_interp_gap {self.max_interp_gap} s: must be >= 0")


@dataclass
class Result:
    """segments : processed DataFrames (bare processed-schema names); report : what was
    found and decided."""

    segments: list[pd.DataFrame]
    report: QualityReport


STAMP_RESOLUTION = 1e-6  # s; a stamp this close to its grid time is on it (a clock time's float)


def _at_grid_times(t: np.ndarray, grid_t: np.ndarray, a: np.ndarray, column: str) -> np.ndarray:
    """Values of one raw column (shape (N,)) moved from their time stamps `t` [s] to the
    grid times `grid_t` [s] (each within 25 ms) by linear interpolation between the column's
    finite samples (extrapolated before the first and after the last): a stamp 10 ms off at
    0.5 m/s is 5 mm of position. Stamps within `STAMP_RESOLUTION` of their grid time, empty
    cells and NaN stamps stay as they are; directions [rad] are interpolated unwrapped and
    returned in [0, 2 pi); GGA fix qualities are codes and are kept as they are."""
    ok = np.isfinite(a) & np.isfinite(t)
    with np.errstate(invalid="ignore"):
        moved = ok & (np.abs(grid_t - t) > STAMP_RESOLUTION)
    if column.endswith("_fix") or ok.sum() < 2 or not moved.any():
        return a
    values = np.unwrap(a[ok]) if column.endswith("_dir") else a[ok]
    tk = t[ok]
    out = a.copy()
    out[moved] = np.interp(grid_t[moved], tk, values)
    for end, pair in ((grid_t < tk[0], slice(0, 2)), (grid_t > tk[-1], slice(-2, None))):
        end &= moved                          # before the first / after the last sample: extrapolate
        if end.any():
            slope = np.diff(values[pair])[0] / np.diff(tk[pair])[0]
            out[end] = values[pair][0] + slope * (grid_t[end] - tk[pair][0])
    if column.endswith("_dir"):
        out[moved] = np.mod(out[moved], 2 * np.pi)
    return out


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) index ranges where `mask` is True."""
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)))


class Pipeline:
    """Runs the ordered steps for one ship's `SensorLayout` with given settings."""

    def __init__(self, layout: SensorLayout, settings: PreprocessSettings = PreprocessSettings()):
        self.layout = layout
        self.settings = settings

    # -- step 1: grid and gaps ------------------------------------------------------------
    def _grid(self, df: pd.DataFrame, name: str, report: dict) -> tuple[np.ndarray, dict]:
        """The columns on the 0.1 s grid (NaN at missing rows) and each grid sample's time
        stamp [s] (NaN where missing). Every column but the GNSS ones is moved from its
        stamps to the grid times here; the GNSS ones after their checks (`_at_grid_times`)."""
        t = df["t"].to_numpy()
        dt = schema.NOMINAL_DT
        k = np.rint((t - t[0]) / dt).astype(np.int64)
        # the grid's phase is the median one, not the first stamp's (whose jitter would
        # shift every output time and every other sample's deviation)
        t0 = t[0] + float(np.median(t - t[0] - k * dt))
        grid_t = t0 + k * dt
        jitter = np.abs(t - grid_t)
        lines = df.attrs.get("line", np.arange(len(t)) + 2)  # each row's line of the file (schema.file_line)
        if jitter.max() > 0.25 * dt:
            row = int(np.argmax(jitter))
            raise RawLogError(f"{name}: column t: line {lines[row]}: {t[row]} s is off the 10 Hz grid")
        if np.any(np.diff(k) == 0):
            row = int(np.flatnonzero(np.diff(k) == 0)[0]) + 1
            raise RawLogError(f"{name}: column t: line {lines[row]}: two samples within one 0.1 s step")
        n = int(k[-1]) + 1
        cols = {}
        for c in df.columns:
            a = np.full(n, np.nan)
            values = df[c].to_numpy()
            a[k] = values if c.startswith("gnss_") else _at_grid_times(t, grid_t, values, c)
            cols[c] = a
        cols["t"] = t0 + np.arange(n) * dt
        stamps = np.full(n, np.nan)
        stamps[k] = t
        report["rows"] = len(t)
        report["missing_rows"] = n - len(t)
        report["time_jitter_max_s"] = float(jitter.max())
        return stamps, cols

    def _fill(self, t: np.ndarray, arrays: list[np.ndarray], channel: str,
              report: dict, angle: bool = False) -> np.ndarray:
        """Interpolate gaps <= max_interp_gap in place; returns the valid mask afterwards."""
        ok = np.all([np.isfinite(a) for a in arrays], axis=0)
        valid = ok.copy()
        if ok.all():
            return valid
        if not ok.any():
            raise RawLogError(f"{report['file']}: column {channel}: no valid sample")
        dt = schema.NOMINAL_DT
        idx = np.flatnonzero(ok)
        for a0, a1 in _runs(~ok):
            dur = (a1 - a0) * dt
            inside = a0 > 0 and a1 < len(t)
            action = "interpolated" if inside and dur <= self.settings.max_interp_gap + 1e-9 else "split"
            report["gaps"].append({"channel": channel, "t_start": round(float(t[a0]), 3),
                                   "t_end": round(float(t[a1 - 1]), 3), "duration_s": round(float(dur), 3),
                                   "action": action if inside else "trimmed"})
            if action == "interpolated":
                valid[a0:a1] = True
        fill = valid & ~ok
        for a in arrays:
            if angle:  # through sin/cos so 2 pi wraps interpolate the short way
                s = np.interp(t[fill], t[idx], np.sin(a[idx]))
                c = np.interp(t[fill], t[idx], np.cos(a[idx]))
                a[fill] = np.mod(np.arctan2(s, c), 2 * np.pi)
            else:
                a[fill] = np.interp(t[fill], t[idx], a[idx])
        return valid

    # -- the run --------------------------------------------------------------------------
    def run(self, raw: pd.DataFrame | str | os.PathLike, name: str | None = None) -> Result:
        """Process a raw log (path, or a DataFrame with the ``name [unit]`` header)."""
        s, lay = self.settings, self.layout
        repairs: list[str] = []
        if isinstance(raw, pd.DataFrame):
            name = name or "<raw log>"
            df, latlon = schema.validate_raw(raw.copy(), name, repairs)
        else:
            name = name or str(raw)
            df, latlon = schema.read_raw(raw, repairs)
        report: dict = {"file": name, "settings": asdict(s), "repairs": repairs, "gaps": [],
                        "segments": [], "dropped_segments": []}
        stamps, g = self._grid(df, name, report)
        t = g["t"]
        dt = schema.NOMINAL_DT

        if latlon:
            self._to_local(g, report)                                     # step 2
        fx, fy, ax, ay = (g[c] for c in ("gnss_fore_x", "gnss_fore_y", "gnss_aft_x", "gnss_aft_y"))
        self._fix_quality(g, (fx, fy, ax, ay), report)

        # step 1 (other channels): interpolate short gaps, mark long ones
        valid = self._fill(t, [g["fog_yaw_rate"]], "fog_yaw_rate", report)
        for k in (1, 2):
            valid &= self._fill(t, [g[f"anemo_{k}_speed"]], f"anemo_{k}_speed", report)
            valid &= self._fill(t, [g[f"anemo_{k}_dir"]], f"anemo_{k}_dir", report, angle=True)
        valid &= self._fill(t, [g["n_prop"]], "n_prop", report)
        valid &= self._fill(t, [g["delta_rudder"]], "delta_rudder", report)

        passed = self._baseline(t, fx, fy, ax, ay, report)                # step 3

        # step 4a: raw heading, swapped-antenna check, FOG units, gating
        psi_g = np.where(passed, gnss.antenna_heading(fx, fy, ax, ay, lay), np.nan)
        if self._swapped(t, psi_g, ax, ay, g["n_prop"]):
            if s.swapped_antennas == "error":
                raise RawLogError(
                    f"{name}: column gnss_fore_x: heading is 180 deg off the course while moving "
                    "ahead: fore and aft antennas swapped? (fix the log, or set "
                    "swapped_antennas='repair' / --swap-antennas)")
            fx, ax, fy, ay = ax, fx, ay, fy
            psi_g = np.where(passed, gnss.antenna_heading(fx, fy, ax, ay, lay), np.nan)
            repairs.append("fore and aft antennas swapped (heading 180 deg off the course)")
        report["swapped_antennas"] = any("swapped" in r for r in repairs)
        psi_fog = cumulative_trapezoid(np.nan_to_num(g["fog_yaw_rate"]), dx=dt, initial=0.0)
        self._check_fog_against_gnss(name, psi_fog, psi_g)
        _, keep, sigma = smoothing.gate_heading(psi_fog, psi_g, dt, s.gate_window,
                                                s.gate_sigma, s.gate_floor)
        rej_gate = passed & ~keep
        report["heading_gate"] = {"rejected": int(rej_gate.sum()),
                                  "rejected_t": [round(float(v), 3) for v in t[rej_gate]],
                                  "gnss_heading_sigma_rad": sigma}
        for a in (fx, fy, ax, ay):
            a[~keep] = np.nan
            # kept fixes only: a rejected one must not leak into its neighbours
            a[:] = _at_grid_times(stamps, t, a, "gnss")
        valid &= self._fill(t, [fx, fy, ax, ay], "gnss", report)

        # segments
        segments = []
        bias_all = []
        min_len = int(round(s.min_segment / dt))
        sparse = 0  # segments left with one sample at the output rate
        for a0, a1 in _runs(valid):
            if a1 - a0 < min_len:
                report["dropped_segments"].append({"t_start": float(t[a0]), "t_end": float(t[a1 - 1]),
                                                   "reason": f"shorter than {s.min_segment} s"})
                continue
            sl = slice(a0, a1)
            seg, bias = self._segment({k: v[sl] for k, v in g.items()}, fx[sl], fy[sl], ax[sl],
                                      ay[sl], keep[sl], np.arange(a0, a1))
            if len(seg) < 2:  # one sample is no run: nothing reads it
                sparse += 1
                report["dropped_segments"].append({"t_start": float(t[a0]), "t_end": float(t[a1 - 1]),
                                                   "reason": f"fewer than 2 samples at {s.output_rate:g} Hz"})
                continue
            bias_all.append(bias)
            segments.append(seg)
            report["segments"].append({"t_start": float(seg["t"].iloc[0]),
                                       "t_end": float(seg["t"].iloc[-1]), "samples": len(seg)})
        if not segments and sparse:
            raise RawLogError(f"{name}: column t: --rate {s.output_rate:g} Hz leaves fewer than 2 samples "
                              "in every segment; choose a higher rate")
        if not segments:
            raise RawLogError(f"{name}: column gnss: no stretch of at least {s.min_segment} s "
                              "without a long gap")
        b = np.concatenate(bias_all)
        report["fog_bias_rad_s"] = {"mean": float(b.mean()), "min": float(b.min()), "max": float(b.max())}
        report["gaps_interpolated"] = sum(1 for x in report["gaps"] if x["action"] == "interpolated")
        report["gaps_split"] = sum(1 for x in report["gaps"] if x["action"] == "split")
        return Result(segments, QualityReport.from_dict(report))

    # -- steps 2 and 3 --------------------------------------------------------------------
    def _to_local(self, g: dict, report: dict) -> None:
        """Step 2: lat/lon [deg] -> gnss_*_x (north), gnss_*_y (east) [m] in `g`."""
        ref = self.settings.reference
        if ref is None:
            found = np.flatnonzero(np.isfinite(g["gnss_aft_lat"]) & np.isfinite(g["gnss_aft_lon"]))
            if not len(found):
                raise RawLogError(f"{report['file']}: column gnss_aft_lat: no GNSS fix in the whole log")
            ref = (float(g["gnss_aft_lat"][found[0]]), float(g["gnss_aft_lon"][found[0]]))
        for a in ("fore", "aft"):
            g[f"gnss_{a}_x"], g[f"gnss_{a}_y"] = geodesy.latlon_to_local(
                g[f"gnss_{a}_lat"], g[f"gnss_{a}_lon"], *ref)
        report["reference_latlon"] = list(ref)

    def _fix_quality(self, g: dict, antennas: tuple, report: dict) -> None:
        """Empty the antenna cells (in place) where a GGA fix quality is not accepted."""
        poor = np.zeros(len(g["t"]), bool)
        for c in ("gnss_fore_fix", "gnss_aft_fix"):
            if c in g:
                poor |= np.isfinite(g[c]) & ~np.isin(g[c], self.settings.accepted_fix)
        for a in antennas:
            a[poor] = np.nan
        report["fix_rejected"] = int(poor.sum())
        if not np.all([np.isfinite(a) for a in antennas], axis=0).any():
            raise RawLogError(f"{report['file']}: column gnss_fore_x: no usable GNSS fix in the whole log")

    def _baseline(self, t, fx, fy, ax, ay, report: dict) -> np.ndarray:
        """Step 3: True where the antenna distance is within tolerance of the nominal one."""
        s, lay = self.settings, self.layout
        have = np.isfinite(fx) & np.isfinite(fy) & np.isfinite(ax) & np.isfinite(ay)
        berr = gnss.baseline_error(fx, fy, ax, ay, lay)
        passed = gnss.baseline_ok(berr, s.baseline_tolerance)
        share = passed.sum() / max(1, have.sum())
        if share < s.min_baseline_pass:
            median = np.nanmedian(berr) + lay.gnss_baseline
            ratio = median / lay.gnss_baseline
            units = {"feet": 1 / 0.3048, "centimetres": 100.0, "millimetres": 1000.0}  # positions logged in them
            unit = next((u for u, k in units.items() if abs(ratio / k - 1) < 0.02), None)
            cause = (f"{ratio:.3g} x the nominal: positions in {unit}? convert the antenna columns to metres"
                     if unit else "check [sensors] gnss_baseline and the antenna columns")
            raise RawLogError(
                f"{report['file']}: column gnss_fore_x: antenna distance median "
                f"{median:.3f} m, nominal {lay.gnss_baseline:.3f} m; "
                f"only {100 * share:.0f}% of fixes within {s.baseline_tolerance} m ({cause})")
        rejected = have & ~passed
        report["baseline"] = {
            "rejected": int(rejected.sum()),
            "rejected_t": [round(float(v), 3) for v in t[rejected]],
            "error_mean_m": float(np.mean(berr[passed])), "error_std_m": float(np.std(berr[passed])),
            "error_max_abs_m": float(np.max(np.abs(berr[passed]))),
            "error_median_all_m": float(np.nanmedian(berr))}
        return passed

    def _swapped(self, t, psi_g, ax, ay, n_prop) -> bool:
        """Heading ~180 deg off the aft antenna's course while the propeller pushes ahead."""
        dt = schema.NOMINAL_DT
        k = max(1, int(round(self.settings.diff_dt / dt)))
        if len(t) <= 2 * k:
            return False
        vx = (ax[2 * k:] - ax[:-2 * k]) / (2 * k * dt)
        vy = (ay[2 * k:] - ay[:-2 * k]) / (2 * k * dt)
        psi = psi_g[k:-k]
        with np.errstate(invalid="ignore"):
            moving = (np.hypot(vx, vy) > 0.2) & (n_prop[k:-k] > 0) & np.isfinite(psi)
        if moving.sum() < 100:
            return False
        c = np.cos(np.arctan2(vy[moving], vx[moving]) - psi[moving])
        return bool(np.mean(c < -0.7) > 0.8)

    @staticmethod
    def _check_fog_against_gnss(name, psi_fog, psi_g) -> None:
        """FOG in deg/s under a rad/s header turns ~57 times too fast against the GNSS; a FOG
        positive to port, or a mirrored local frame, turns against it."""
        step = 10
        ok = np.isfinite(psi_g)
        i = np.flatnonzero(ok)
        if len(i) < 2 * step:
            return
        dg = np.diff(np.unwrap(psi_g[i]))
        df = np.diff(psi_fog[i])
        big = np.abs(dg) < 0.5
        turn = float(np.sum(np.abs(dg[big])))
        if turn < 1.0:
            return  # too little turning to tell
        ratio = float(np.sum(np.abs(df[big])) / turn)
        if ratio > 10.0:
            raise RawLogError(f"{name}: column fog_yaw_rate: turns {ratio:.0f} times faster than the "
                              "GNSS heading: degrees in a radian column?")
        # 1-s heading changes of gyro and antennas: opposite signs mean a gyro counted positive
        # to port, or a local frame mirrored (x east, y north); either way psi and r are wrong
        unwrapped = np.full(len(psi_g), np.nan)
        unwrapped[i] = np.unwrap(psi_g[i])
        d_gnss = unwrapped[step:] - unwrapped[:-step]
        d_fog = psi_fog[step:] - psi_fog[:-step]
        with np.errstate(invalid="ignore"):
            m = np.isfinite(d_gnss) & (np.abs(d_gnss) < 0.5)
        turned = float(np.sum(np.abs(d_fog[m]))) / step     # rad turned by the gyro's account
        if m.sum() < 10 * step or turned < 1.0:
            return
        corr = float(np.sum(d_gnss[m] * d_fog[m]) / np.sqrt(np.sum(d_gnss[m] ** 2) * np.sum(d_fog[m] ** 2)))
        if corr < -0.5:
            raise RawLogError(
                f"{name}: column fog_yaw_rate: the gyro turns against the two-antenna heading "
                f"(correlation {corr:.2f} of their 1-s changes over {turned:.1f} rad of turning): a gyro "
                "counted positive to port (z up)? negate the column (sysid's yaw rate is positive to "
                "starboard); or antenna x, y with x east and y north? sysid's local frame is x north, "
                "y east: swap the x and y columns")

    def _segment(self, g: dict, fx, fy, ax, ay, measured, grid_index
                 ) -> tuple[pd.DataFrame, np.ndarray]:
        """Steps 4-10 on one gap-free segment (10 Hz arrays); `measured` marks real GNSS
        fixes (interpolated ones give positions but no heading measurement)."""
        s, lay = self.settings, self.layout
        dt = schema.NOMINAL_DT
        fog = g["fog_yaw_rate"]
        psi_fog = cumulative_trapezoid(fog, dx=dt, initial=0.0)
        # step 4: fused heading (gating already done on the whole run)
        psi_g = gnss.antenna_heading(fx, fy, ax, ay, lay)
        z = np.unwrap(psi_fog - psi_g)
        z[~measured] = np.nan
        heading_noise = np.sqrt(2.0) * s.gnss_noise / lay.gnss_baseline
        psi, bias = smoothing.fuse_heading(psi_fog, z, dt, s.fog_noise, s.fog_bias_walk, heading_noise)
        # step 5: midship position
        x, y = gnss.midship_position(fx, fy, ax, ay, psi, lay)
        # step 6: central difference (earth frame) -> body frame, rotated by the heading
        # over each difference's window (not psi(t) alone: that lags v_m while turning)
        u_cd, v_cd = body_velocity.body_velocity(x, y, psi, dt, s.diff_dt)
        # step 7: Kalman/RTS on u, v_m; the narrower differences near the ends weigh less
        scale = differencing.noise_scale(len(x), dt, s.diff_dt)
        u = smoothing.smooth_rate(u_cd, dt, s.velocity_q, s.velocity_r, scale)
        v = smoothing.smooth_rate(v_cd, dt, s.velocity_q, s.velocity_r, scale)
        # step 8: r = low-passed FOG minus the estimated bias
        r = gyro.lowpass(fog - bias, 1.0 / dt, s.cutoff, s.lowpass_order)
        # step 9: wind
        ut, gt, ua, ga = anemometer.combine(
            [(g["anemo_1_speed"], g["anemo_1_dir"]), (g["anemo_2_speed"], g["anemo_2_dir"])],
            u, v, r, psi, [lay.anemometer_1, lay.anemometer_2])
        # step 10: take samples
        step = int(round(1.0 / (s.output_rate * dt)))
        i = resample.sample_indices(grid_index, step)
        out = pd.DataFrame({   # t + 0.0: a grid phase a hair below 0 s is written 0.0, not -0.0
            "t": np.round(g["t"][i], 6) + 0.0, "x_position_mid": x[i], "u_velo": u[i],
            "y_position_mid": y[i], "vm_velo": v[i], "psi_hat": wrap_pi(psi[i]),
            "r_angvelo": r[i], "n_prop": g["n_prop"][i], "delta_rudder": g["delta_rudder"][i],
            "wind_velo_relative_mid": ua[i], "wind_dir_relative_mid": ga[i],
            "wind_velo_true": ut[i], "wind_dir_true": gt[i]})
        return out, bias


def process_file(path: str, layout: SensorLayout, settings: PreprocessSettings, outdir: str
                 ) -> dict:
    """Process one raw log and write its outputs (a worker for process pools).

    Returns {'file', 'ok', 'error' | 'outputs', 'report'}; a failed file writes nothing, and
    its 'bad_input' says whether the log is at fault (`RawLogError`) rather than sysid.
    """
    from preprocessing import writer
    try:
        result = Pipeline(layout, settings).run(path)
        stem = os.path.splitext(os.path.basename(path))[0]
        try:
            outputs = writer.write_segments(outdir, stem, result.segments, result.report)
        except OSError as exc:  # the output's fault (a full disk), not the log's: the caller stops
            return {"file": str(path), "ok": False, "write_error": exc.errno,
                    "error": f"writing the output of {path} failed: {exc.strerror or exc}"}
        return {"file": str(path), "ok": True, "outputs": [str(p) for p in outputs],
                "report": result.report}
    except RawLogError as exc:
        return {"file": str(path), "ok": False, "error": str(exc), "bad_input": True}
    except Exception as exc:  # anything else is a bug, but one file must not stop the rest
        return {"file": str(path), "ok": False, "error": f"{path}: internal error: {exc!r}", "bad_input": False}
