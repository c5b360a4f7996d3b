"""Raw and processed log schemas (column names and units), reading and validation.

Headers are ``name [unit]`` as in the public FRT-DS-ESSO files. `read_raw` returns a
DataFrame with the bare names (``t``, ``gnss_fore_x``, ...) in SI units, or raises
`RawLogError` naming the file, the column and the row as the file's line (`file_line`: the
header is line 1, the first data row line 2), so an editor opens the file at it.
Documented repairs (degree headers converted to radians, exact duplicate rows dropped) are
appended to the `repairs` list the caller passes in.
"""
from __future__ import annotations

import difflib
import os
from pathlib import Path

import numpy as np
import pandas as pd

from preprocessing.channels import PROCESSED, PROCESSED_CHANNEL  # noqa: F401 (the processed schema, re-exported)


class RawLogError(ValueError):
    """A raw log cannot be processed: missing column, wrong unit, bad time, bad geometry."""


# bare name -> unit, raw log
def file_line(index: int) -> int:
    """The line of a CSV file holding the data row whose pandas index (as `pd.read_csv` numbers
    the rows, from 0) is `index`: the header is line 1, so line index + 2."""
    return int(index) + 2


RAW_COMMON = {
    "t": "s",
    "fog_yaw_rate": "rad/s",
    "anemo_1_speed": "m/s", "anemo_1_dir": "rad",
    "anemo_2_speed": "m/s", "anemo_2_dir": "rad",
    "n_prop": "rps",
    "delta_rudder": "rad",
}
RAW_LOCAL = {"gnss_fore_x": "m", "gnss_fore_y": "m", "gnss_aft_x": "m", "gnss_aft_y": "m"}
RAW_LATLON = {"gnss_fore_lat": "deg", "gnss_fore_lon": "deg",
              "gnss_aft_lat": "deg", "gnss_aft_lon": "deg"}
RAW_OPTIONAL = {"gnss_fore_fix": "-", "gnss_aft_fix": "-"}

# plausibility limits of a processed run (channel names, SI); beyond means wrong units. A
# heading beyond one turn either way is degrees (processed headings are wrapped) unless it
# changes at the yaw rate (unwrapped radians, `sysid.data.read_run`); 3 rad/s (172 deg/s) is
# six times the fastest turn of a ship model (< 0.5 rad/s)
PROCESSED_PLAUSIBLE_ABS = {"u": 20.0, "v": 20.0, "psi": 2 * np.pi, "r": 3.0, "delta_rudder": 1.6,
                           "wind_dir_true": 7.0, "wind_dir_relative": 7.0, "n_prop": 200.0, "wind_velo_true": 60.0}

# headers accepted for a column of another unit, converted (a logged repair): degrees for
# radians, rpm for rps
_CONVERTED_UNITS = {"rad": ("deg", np.pi / 180.0), "rad/s": ("deg/s", np.pi / 180.0), "rps": ("rpm", 1.0 / 60.0)}

# plausibility limits in SI units; a value beyond means wrong units (e.g. degrees in rad)
PLAUSIBLE_ABS = {
    "fog_yaw_rate": 1.5,          # rad/s; a ship model turns < 0.5 rad/s
    "delta_rudder": 1.0,          # rad; rudders stop near 35-45 deg
    "anemo_1_dir": 2 * np.pi + 0.01, "anemo_2_dir": 2 * np.pi + 0.01,
    "anemo_1_speed": 60.0, "anemo_2_speed": 60.0,
    "n_prop": 100.0,
}
PLAUSIBLE_MIN = {"anemo_1_dir": -np.pi - 0.01, "anemo_2_dir": -np.pi - 0.01,
                 "anemo_1_speed": 0.0, "anemo_2_speed": 0.0}

NOMINAL_DT = 0.1  # s, raw log step
ABSOLUTE_TIME_S = 86400.0  # s; a first time stamp a day or more: a clock time, not time since the start


def header(columns: dict[str, str]) -> list[str]:
    """``name [unit]`` headers for a name -> unit mapping."""
    return [f"{k} [{u}]" if u != "-" else k for k, u in columns.items()]


def _split_header(h: str) -> tuple[str, str | None]:
    h = h.strip()
    if h.endswith("]") and " [" in h:
        name, unit = h[:-1].split(" [", 1)
        return name.strip(), unit.strip()
    return h, None


def _need(have: dict[str, str | None], names: dict[str, str], path: str, repairs: list[str],
          scale: dict[str, float]) -> None:
    """Check presence and unit of each column; record degree->radian repairs in `scale`."""
    for name, unit in names.items():
        if name not in have:
            known = {**RAW_COMMON, **RAW_LOCAL, **RAW_LATLON, **RAW_OPTIONAL}  # each needed as itself
            close = difflib.get_close_matches(name, [h for h in have if h not in known], n=1, cutoff=0.6)
            fix = (f"found {close[0]!r}: misnamed? rename it" if close else
                   "add it (a raw log's columns: docs, Input formats, Raw logs)")
            raise RawLogError(f"{path}: column {name} [{unit}]: missing; {fix}")
        got = have[name]
        if got is None or got == unit:
            continue
        if unit in _CONVERTED_UNITS and got == _CONVERTED_UNITS[unit][0]:
            scale[name] = _CONVERTED_UNITS[unit][1]
            repairs.append(f"column {name}: header unit [{got}], converted to [{unit}]")
            continue
        raise RawLogError(f"{path}: column {name}: unit [{got}], expected [{unit}]")


def validate_raw(df: pd.DataFrame, path: str = "<raw log>",
                 repairs: list[str] | None = None) -> tuple[pd.DataFrame, bool]:
    """Validate a raw log read with its ``name [unit]`` header.

    Returns (frame with bare-name columns in SI units, has_latlon). Raises `RawLogError`.
    Empty cells stay NaN (GNSS dropouts); the gap logic of the pipeline handles them.
    """
    repairs = [] if repairs is None else repairs
    have: dict[str, str | None] = {}
    for col in df.columns:
        name, unit = _split_header(str(col))
        have[name] = unit
    processed = [name for name in ("x_position_mid", "u_velo", "psi_hat", "r_angvelo") if name in have]
    if processed and "fog_yaw_rate" not in have:
        raise RawLogError(f"{path}: columns {', '.join(processed)}: a processed log, not a raw 10 Hz one; "
                          "train, evaluate and simulate read it as it is (preprocess reads raw logs)")
    scale: dict[str, float] = {}
    _need(have, RAW_COMMON, path, repairs, scale)
    if all(k in have for k in RAW_LOCAL):
        gnss, latlon = RAW_LOCAL, False
    elif all(k in have for k in RAW_LATLON):
        gnss, latlon = RAW_LATLON, True
    else:
        partial = [k for k in list(RAW_LOCAL) + list(RAW_LATLON) if k in have]
        form = RAW_LATLON if any(k in RAW_LATLON for k in partial) else RAW_LOCAL
        _need(have, form, path, repairs, scale)  # raises on the first missing one
        raise RawLogError(f"{path}: GNSS columns incomplete")  # pragma: no cover
    _need(have, gnss, path, repairs, scale)
    empty = df.isna().all(axis=1).to_numpy()
    if len(empty) and empty.all():
        raise RawLogError(f"{path}: no data: every one of its {len(empty)} rows is empty (no number in any column)")
    if empty.any():  # blank lines, typically trailing ones from spreadsheet exports
        repairs.append(f"dropped {int(empty.sum())} empty row(s), first at line "
                       f"{file_line(df.index[np.flatnonzero(empty)[0]])}")
        df = df.loc[~empty]
    out = pd.DataFrame({_split_header(str(c))[0]: df[c] for c in df.columns})
    keep = list(RAW_COMMON) + list(gnss) + [k for k in RAW_OPTIONAL if k in have]
    out = out[keep]
    for col in out.columns:
        values = pd.to_numeric(out[col], errors="coerce")
        bad = values.isna() & out[col].notna()
        if bad.any():
            first = int(np.flatnonzero(bad.to_numpy())[0])
            raise RawLogError(f"{path}: column {col}: line {file_line(out.index[first])}: not a number "
                              f"({out[col].iloc[first]!r})")
        values = values.astype(float)
        inf = np.isinf(values.to_numpy())
        if inf.any():
            raise RawLogError(f"{path}: column {col}: line {file_line(out.index[np.flatnonzero(inf)[0]])}: "
                              "infinite value")
        out[col] = values * scale.get(col, 1.0)
    out = _check_time(out, path, repairs)
    _check_ranges(out, path)
    lines = out.index.to_numpy() + 2  # each kept row's line of the file (`file_line`)
    out = out.reset_index(drop=True)
    out.attrs["line"] = lines          # for the pipeline's own row errors
    return out, latlon


def _check_time(df: pd.DataFrame, path: str, repairs: list[str]) -> pd.DataFrame:
    """Strictly increasing time; exact duplicate rows are dropped (a logged repair)."""
    t = df["t"].to_numpy()
    if len(t) < 2:
        raise RawLogError(f"{path}: column t: fewer than 2 rows")
    nan = np.isnan(t)
    if nan.any():
        raise RawLogError(f"{path}: column t: line {file_line(df.index[np.flatnonzero(nan)[0]])}: empty time ({int(nan.sum())} "
                          "row(s); every row needs its time stamp: fill it in, or delete the row)")
    dup = df.duplicated(keep="first").to_numpy()
    if dup.any():
        rows = np.flatnonzero(dup)
        repairs.append(f"dropped {len(rows)} exact duplicate row(s), first at line {file_line(df.index[rows[0]])}")
        df = df.loc[~dup]
        t = df["t"].to_numpy()
    step = np.diff(t)
    bad = np.flatnonzero(step <= 0.0)
    if len(bad):
        what = "repeated time with different values" if step[bad[0]] == 0 else "time goes backwards"
        raise RawLogError(f"{path}: column t: line {file_line(df.index[bad[0] + 1])}: {what} (t = {t[bad[0] + 1]} s after "
                          f"{t[bad[0]]} s)")
    med = float(np.median(step))
    if abs(med - NOMINAL_DT) > 0.02:
        raise RawLogError(f"{path}: column t: median step {med:.4f} s, expected {NOMINAL_DT} s "
                          "(10 Hz log; time in ms?)")
    if t[0] >= ABSOLUTE_TIME_S:   # a clock time (Unix seconds): the processed log counts from the run's start
        repairs.append(f"column t: starts at {t[0]:.1f} s, a clock time; counted from the first sample")
        df = df.assign(t=t - t[0])
    return df


# the likely cause of a value beyond PLAUSIBLE_ABS, and its fix, by the column's unit
_RANGE_FIX = {
    "rad": "degrees in a radian column? label the column [deg] and sysid converts it",
    "rad/s": "degrees per second in a rad/s column? label the column [deg/s] and sysid converts it",
    "m/s": "knots or km/h in an m/s column? convert the column to m/s",
    "rps": "rpm in an rps column? convert the column to rps (rpm / 60)",
}


def _check_ranges(df: pd.DataFrame, path: str) -> None:
    """Values within PLAUSIBLE_ABS (and PLAUSIBLE_MIN); beyond: one error naming the file, the
    column, the first row outside, the most extreme value and the likely unit fix."""
    for col, lim in PLAUSIBLE_ABS.items():
        v = df[col].to_numpy()
        lo = PLAUSIBLE_MIN.get(col, -lim)
        bad = np.flatnonzero((v > lim) | (v < lo))
        if len(bad):
            unit = RAW_COMMON[col]
            worst = bad[np.argmax(np.abs(v[bad]))]
            low = bool(np.all(v[bad] < lo))
            fix = f"a negative {col}: the sensor's offset or sign?" if low and lo == 0.0 else _RANGE_FIX[unit]
            raise RawLogError(
                f"{path}: column {col}: line {file_line(df.index[bad[0]])}: {len(bad)} row(s) outside "
                f"[{lo:.3g}, {lim:.3g}] {unit}, up to {v[worst]:.6g} (line {file_line(df.index[worst])}): {fix}")


def read_raw(path: str | os.PathLike, repairs: list[str] | None = None) -> tuple[pd.DataFrame, bool]:
    """Read and validate a raw CSV log; see `validate_raw`."""
    path = Path(path)
    if not path.is_file():
        raise RawLogError(f"{path}: file not found")
    try:
        df = pd.read_csv(path, skipinitialspace=True, skip_blank_lines=False)   # a blank line: an empty row
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise RawLogError(f"{path}: not a readable CSV ({exc})") from None
    _check_last_row(path, len(df.columns), len(df))
    return validate_raw(df, str(path), repairs)


def _check_last_row(path: Path, n_columns: int, n_rows: int) -> None:
    """A file cut off in its last row (a copy or download that stopped): that row has fewer
    fields than the header, and its last one may be cut too; `RawLogError` naming it."""
    with open(path, "rb") as f:
        f.seek(max(0, os.path.getsize(path) - 65536))
        tail = f.read()
    if not tail or tail.endswith(b"\n") or tail.endswith(b"\r"):
        return
    fields = tail.rsplit(b"\n", 1)[-1].count(b",") + 1
    if fields < n_columns:
        raise RawLogError(f"{path}: line {file_line(n_rows - 1)}: {fields} of {n_columns} fields and no line end: the file "
                          "is cut off (an interrupted copy?); copy it again, or delete its last row")
