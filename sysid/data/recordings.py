"""Processed runs at 1 Hz, checked, and cut into windows.

A processed file (CSV or Parquet) has the 13 columns of the processed schema, headers
``name [unit]`` (``u_velo [m/s]``, ...; `sysid.data.columns.DEFAULT_COLUMNS`), at 10 Hz (the
public FRT-DS-ESSO files) or 1 Hz (``sysid preprocess`` output), or any columns and units
that a config's ``[data.columns]`` maps onto the channels (`sysid.data.columns`). `read_run`
drops trailing all-empty rows, rejects NaN inside the run, non-monotonic time and wrong
units, and downsamples by taking every k-th sample from the first one (t = 0, 1, 2 s), saying so
once per process (a 10 Hz log read at 1 Hz); a rate that is not a whole number of the file's
samples per step, or above the file's own, is refused.
"""
from __future__ import annotations

import glob
import logging
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Collection, Iterable, Sequence

import numpy as np
import pandas as pd
import torch

from preprocessing.schema import PROCESSED, PROCESSED_CHANNEL, PROCESSED_PLAUSIBLE_ABS
from sysid.data.columns import QUANTITY, RELATIVE_WIND, SI_UNIT, ColumnMap, to_channels
from sysid.data.consistency import TrackCheck, check_track, report_checks
from sysid.data.csvfiles import LOG_SUFFIXES, not_a_file, read_table, row_name
from sysid.errors import DataError
from sysid.mmg.wind import relative_wind
from sysid.channel_names import INPUTS, STATE

# processed-schema header ("u_velo [m/s]") -> our channel name ("u"); one source: preprocessing.schema
COLUMNS = {f"{name} [{unit}]": PROCESSED_CHANNEL[name] for name, unit in PROCESSED.items()}
HEADER = {channel: header for header, channel in COLUMNS.items()}
_LIMITS = PROCESSED_PLAUSIBLE_ABS
_log = logging.getLogger(__name__)


@dataclass
class Run:
    """One processed run at a uniform rate.

    Attributes
    ----------
    name : file stem; path : source file.
    t : (N,) time [s]; states : (N, 6) x, u, y, v, psi, r; inputs : (N, 4) n_prop [rps],
    delta_rudder [rad], wind_velo_true [m/s], wind_dir_true [rad]; relative_wind : (N, 2)
    U_A [m/s], gamma_A [rad] as recorded.
    dt : sample period [s]; issues : data-quality findings (gaps, frozen GNSS, ...);
    suspect : (t_start, t_end) [s] intervals of frozen GNSS or time gaps.
    stride : samples of the file per sample of the run (10: a 10 Hz file read at 1 Hz).
    sha256 : SHA-256 of the source file when known (a run shipped to a node without the
    file carries it); None: hashed from `path` when needed.
    track : the log's channels against its own GNSS track (`sysid.data.consistency`), at the
    file's own rate.
    """

    name: str
    path: Path
    t: np.ndarray
    states: np.ndarray
    inputs: np.ndarray
    relative_wind: np.ndarray
    dt: float
    issues: list[str] = field(default_factory=list)
    suspect: list[tuple[float, float]] = field(default_factory=list)
    sha256: str | None = None
    track: TrackCheck | None = None
    stride: int = 1

    def __len__(self) -> int:
        return len(self.t)

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0]) if len(self.t) else 0.0


def read_run(path: str | os.PathLike, rate: float = 1.0, columns: ColumnMap | None = None,
             warn=_log.warning, rudder_sign_checked: Collection[str] = ()) -> Run:
    """Read and check a processed run (CSV or Parquet), downsampled to `rate` [Hz] by taking
    samples. `columns` maps the log's own column names and units onto the channels
    (``[data.columns]``; default: the processed schema's headers). The log is checked
    against its own GNSS track, and its rudder's sign against its yaw response
    (`sysid.data.consistency`): a clear mismatch is a `DataError` naming the file, the
    channel and the factor (or the fix); a marginal one, or a log
    without a track, goes to `warn` (None: silent). A log named (by its file's stem) in
    `rudder_sign_checked` (``[data] rudder_sign_checked``) is read whatever its rudder check
    says, the override recorded in its `Run.track` and said to `warn`."""
    path = Path(path)
    columns = columns if columns is not None else ColumnMap()
    if not (rate > 0 and np.isfinite(rate)):
        raise DataError(f"{path}: rate {rate} Hz: must be > 0")
    frame, recorded = _channels(path, columns)
    if len(recorded) < len(frame.columns):  # no relative wind recorded: from the state and true wind
        frame = frame.assign(**dict(zip(RELATIVE_WIND, _relative_wind(frame))))
    values = frame.to_numpy(dtype=float)
    t = values[:, 0]
    steps = np.diff(t)
    if (steps <= 0).any():
        row = int(np.argmax(steps <= 0)) + 1
        raise DataError(f"{path}: {columns.describe('t')} (channel t) is not strictly increasing at "
                        f"{row_name(path, row)} (t = {t[row]} s)")
    beyond = []
    for name, limit in _LIMITS.items():
        peak = np.abs(frame[name].to_numpy()).max()
        if name == "psi" and peak > limit and _turns_at_yaw_rate(t, frame["psi"].to_numpy(), frame["r"].to_numpy()):
            continue  # an unwrapped heading in radians (a simulated turn): it changes at r
        if peak > limit:
            beyond.append((name, peak, limit))
    if beyond:  # every channel in the wrong units, in one line
        listed = "; ".join(f"{columns.describe(name)} (channel {name}) reaches {peak:.4g} {SI_UNIT[name]}, "
                           f"beyond {limit}" for name, peak, limit in beyond)
        hints = ", ".join(f"{name} = {{ column = \"...\", unit = \"{_UNIT_HINT[QUANTITY[name]]}\" }}"
                          for name, _, _ in beyond)
        raise DataError(f"{path}: {listed}: wrong units? name {'its unit' if len(beyond) == 1 else 'their units'} "
                        f"in [data.columns], e.g. {hints}")
    # after the plausible ranges (every channel beyond its range named in one line): the track
    # check finds the subtler faults (knots, a flipped sign, swapped channels)
    c = {name: frame[name].to_numpy() for name in ("x", "y", "psi", "u", "v", "r")}
    track = check_track(path, t, c["x"], c["y"], c["psi"], c["u"], c["v"], c["r"], columns,
                        delta=frame["delta_rudder"].to_numpy())
    if path.stem in rudder_sign_checked:
        track = track.rudder_sign_checked()
    report_checks([track], warn)
    period = float(np.median(steps))
    stride = int(round(1.0 / rate / period))
    if stride < 1 or abs(stride * period * rate - 1.0) > 1e-3:
        raise DataError(f"{path}: rate {rate:g} Hz is not a whole number of this file's {period:g}-s samples "
                        f"per step; choose a rate that divides {1.0 / period:g} Hz")
    if stride > 1:
        _note_resampled(path, 1.0 / period, rate, stride)
    issues, suspect = _quality_issues(t, values, period)
    sel = values[::stride]
    if len(sel) < 2:
        raise DataError(f"{path}: rate {rate:g} Hz leaves {len(sel)} sample of this {t[-1] - t[0]:.0f}-s run; "
                        "choose a higher rate")
    return Run(
        name=path.stem, path=path, t=sel[:, 0],
        states=sel[:, [frame.columns.get_loc(c) for c in list(STATE)]],
        inputs=sel[:, [frame.columns.get_loc(c) for c in list(INPUTS)]],
        relative_wind=sel[:, [frame.columns.get_loc("wind_velo_relative"),
                              frame.columns.get_loc("wind_dir_relative")]],
        dt=period * stride, issues=issues, suspect=suspect, track=track, stride=stride)


_NOTED: set[tuple[float, float]] = set()   # (file rate, read rate) pairs already said, once per process


def _note_resampled(path: Path, file_rate: float, rate: float, stride: int) -> None:
    """Say once per process and pair of rates that logs are read at a lower rate than they
    were written (a stage line naming the first such file)."""
    key = (round(file_rate, 6), round(rate, 6))
    if key in _NOTED:
        return
    _NOTED.add(key)
    _log.info(f"{path.name} (and any other log at {file_rate:g} Hz): read at {rate:g} Hz, every {stride}th sample "
              f"from the first (processed logs are already smoothed, so no filter); [data] rate sets the rate")


def read_runs(paths: Iterable[str | os.PathLike], rate: float = 1.0, columns: ColumnMap | None = None,
              warn=_log.warning, rudder_sign_checked: Collection[str] = ()) -> list[Run]:
    """`read_run` of each file (`rudder_sign_checked`: the logs whose rudder sign the user checked); the errors of all files (a clear mismatch with its track
    in several logs, ...) as one `DataError`, a line per file. Logs without a track are
    named once. Two files of one name (``a/log.csv``, ``b/log.csv``) are refused: a log is
    named by its file's stem in windows, cells, traces and tables."""
    runs, errors = [], []
    first: dict[str, Path] = {}
    for path in paths:   # an iterator (a progress bar) is read once, as the files are
        stem = Path(path).stem
        if stem in first:
            same = first[stem].resolve() == Path(path).resolve()
            raise DataError(f"{path}: " + ("given twice" if same else f"the same name as {first[stem]}")
                            + f"; sysid names a log by its file name ({stem!r}): "
                            + ("give it once" if same else "rename one of them"))
        first[stem] = Path(path)
        try:
            runs.append(read_run(path, rate, columns, warn=None, rudder_sign_checked=rudder_sign_checked))
        except DataError as exc:
            errors.append(str(exc))
    if errors:
        raise DataError("\n".join(errors))
    report_checks([r.track for r in runs if r.track is not None], warn)
    return runs


def _channels(path: Path, columns: ColumnMap) -> tuple[pd.DataFrame, list[str]]:
    """(the log's channels (`ColumnMap.to_channels`) without trailing all-empty rows, the
    channels recorded); `DataError` for fewer than two rows or an empty cell inside."""
    raw = read_table(path, "a processed run with the header 'name [unit]', or columns named in [data.columns]")
    frame = to_channels(columns, raw, path)
    # trailing all-empty rows (zigzag 13_50_28 ends with 327 of them) are dropped
    recorded = [c for c in frame.columns if c not in RELATIVE_WIND or frame[c].notna().any()]
    values = frame[recorded].to_numpy(dtype=float)
    filled = ~np.isnan(values[:, 1:]).all(axis=1)
    last = int(np.nonzero(filled)[0][-1]) + 1 if filled.any() else 0
    frame, values = frame.iloc[:last], values[:last]
    if len(frame) < 2:
        raise DataError(f"{path}: fewer than two data rows")
    bad = ~np.isfinite(values)
    if bad[-1].any() and not bad[:-1].any() and _ends_mid_row(path):
        raise DataError(f"{path}: {row_name(path, len(frame) - 1)}: the file ends in the middle of it (no line end, "
                        f"{int(bad[-1].sum())} of {bad.shape[1]} channels missing): it is cut off (an interrupted "
                        "copy?); copy it again, or delete its last row")
    if bad.any():   # every channel with an empty cell, in one line
        listed = "; ".join(f"{columns.describe(channel)} (channel {channel}) is empty, NaN or inf at "
                           f"{row_name(path, int(np.argmax(bad[:, j])))}" for j, channel in enumerate(recorded) if bad[:, j].any())
        raise DataError(f"{path}: {listed} ({int(bad.any(axis=1).sum())} bad rows)")
    return frame, recorded


def _ends_mid_row(path: Path) -> bool:
    """A CSV file whose last byte ends no line (a copy or download that stopped mid-row)."""
    if path.suffix.lower() != ".csv":
        return False
    with open(path, "rb") as f:
        f.seek(max(0, path.stat().st_size - 1))
        last = f.read(1)
    return last not in (b"\n", b"\r", b"")


def log_track(path: str | os.PathLike, columns: ColumnMap | None = None,
              rudder_sign_checked: Collection[str] = ()) -> TrackCheck:
    """A log's channels against its own GNSS track and its rudder's sign against its yaw
    response (`sysid.data.consistency.check_track`) at the file's own rate, whatever the other checks of `read_run` say; `DataError` when
    the channels cannot be read. A log named in `rudder_sign_checked` has its reversed rudder
    marked as the user's (`TrackCheck.rudder_sign_checked`)."""
    path = Path(path)
    columns = columns if columns is not None else ColumnMap()
    frame, _ = _channels(path, columns)
    c = {name: frame[name].to_numpy() for name in ("t", "x", "y", "psi", "u", "v", "r", "delta_rudder")}
    if (np.diff(c["t"]) <= 0).any():
        return TrackCheck(path, reason="time not strictly increasing")
    found = check_track(path, c["t"], c["x"], c["y"], c["psi"], c["u"], c["v"], c["r"], columns,
                        delta=c["delta_rudder"])
    return found.rudder_sign_checked() if path.stem in rudder_sign_checked else found


_UNIT_HINT = {"speed": "knots", "angle": "deg", "angular rate": "deg/s", "revolutions": "rpm"}


def _relative_wind(frame: pd.DataFrame) -> tuple[np.ndarray, np.ndarray]:
    """(U_A [m/s], gamma_A [rad]) at midship from the recorded state and true wind."""
    c = {k: torch.tensor(frame[k].to_numpy(), dtype=torch.float64)
         for k in ("u", "v", "psi", "wind_velo_true", "wind_dir_true")}
    wind = relative_wind(c["u"], c["v"], c["psi"], c["wind_velo_true"], c["wind_dir_true"])
    return wind[0].numpy(), wind[1].numpy()


def _turns_at_yaw_rate(t: np.ndarray, psi: np.ndarray, r: np.ndarray) -> bool:
    """Whether heading psi changes at the yaw rate r [rad/s], as an unwrapped heading in
    radians does, and not 57 times faster (degrees): the least-squares factor between
    dpsi/dt and r, over steps without a wrap, lies within a factor 2 of 1."""
    dpsi = np.diff(psi)
    keep = np.abs(dpsi) < np.pi
    rate, r_mid = dpsi[keep] / np.diff(t)[keep], 0.5 * (r[1:] + r[:-1])[keep]
    power = float(r_mid @ r_mid)
    return power > 0 and 0.5 < float(rate @ r_mid) / power < 2.0


def _quality_issues(t: np.ndarray, values: np.ndarray, period: float):
    """Gaps in time and frozen GNSS (position and heading constant for >= 1 s):
    messages and (t_start, t_end) intervals."""
    issues, suspect = [], []
    steps = np.diff(t)
    for i in np.nonzero(steps > 1.5 * period)[0]:
        issues.append(f"time gap of {steps[i]:.2f} s at t = {t[i]:.1f} s")
        suspect.append((float(t[i]), float(t[i + 1])))
    frozen = (np.diff(values[:, 1]) == 0) & (np.diff(values[:, 5]) == 0)  # x and psi unchanged
    run_len = max(2, int(round(1.0 / period)))
    # each run of frozen steps [i, j): where the padded flags change, starts and ends alternate
    edges = np.flatnonzero(np.diff(np.concatenate(([False], frozen, [False])).astype(np.int8)))
    for i, j in zip(edges[0::2], edges[1::2]):
        if j - i >= run_len:
            issues.append(f"GNSS frozen for {t[j] - t[i]:.1f} s at t = {t[i]:.1f} s")
            suspect.append((float(t[i]), float(t[j])))
    return issues, suspect


def duplicate_runs(runs: Sequence[Run], tolerance: float = 1e-9) -> list[tuple[str, str]]:
    """Pairs (copy, original) where one run's samples are the start of another's.

    ``turn_cut_14-Sep-2020_15_58_08`` is the first 286.8 s of ``turn_14-Sep-2020_15_58_08``;
    a window-level split would otherwise put copies in training and validation.
    """
    pairs = []
    for a in runs:
        for b in runs:
            if a is b or len(a) > len(b) or (len(a) == len(b) and a.name > b.name):
                continue
            n = len(a)
            if np.allclose(a.states, b.states[:n], atol=tolerance) and \
                    np.allclose(a.inputs, b.inputs[:n], atol=tolerance):
                pairs.append((a.name, b.name))
    return pairs


def expand_paths(items: Iterable[str | os.PathLike]) -> list[Path]:
    """Files, directories (searched recursively for .csv and .parquet logs) and glob patterns
    (``logs/*.csv``, ``logs/**/*.parquet``; matches sorted) to a file list."""
    out: list[Path] = []
    from sysid.store.manifest import has_manifest, verify_manifest

    for item in items:
        p = Path(item)
        if not p.exists() and glob.has_magic(str(item)):
            matches = sorted(Path(m) for m in glob.glob(str(item), recursive=True) if Path(m).is_file())
            if not matches:
                raise DataError(f"{item}: no file matches this pattern")
            out += matches
            continue
        if p.is_dir():
            if has_manifest(p):  # sysid preprocess output: refused when incomplete or changed
                verify_manifest(p)
            # hidden entries are staging directories and temporaries of unfinished writes
            found = sorted(q for q in p.rglob("*") if q.suffix.lower() in LOG_SUFFIXES
                           and not q.name.endswith(".truth.csv")
                           and not any(part.startswith(".") for part in q.relative_to(p).parts))
            if not found:
                raise DataError(f"{p}: directory holds no .csv or .parquet files")
            out += found
        elif p.is_file():
            out.append(p)
        elif p.exists():
            raise DataError(f"{p}: {not_a_file(p)}")
        else:
            raise DataError(f"{p}: no such file or directory")
    return out


def protocol_windows(n_samples: int, horizon: int) -> np.ndarray:
    """Start indices of consecutive, non-overlapping full windows of `horizon` samples
    (k = 0 .. floor(N / H) - 1; docs: the paper's protocol, the metric)."""
    return np.arange(n_samples // horizon) * horizon


def sliding_windows(n_samples: int, length: int, stride: int) -> np.ndarray:
    """Start indices of windows of `length` samples slid by `stride` samples."""
    if n_samples < length:
        return np.zeros(0, dtype=int)
    return np.arange(0, n_samples - length + 1, stride)


def window_touches(run: Run, starts: np.ndarray, length: int, margin_s: float = 1.0) -> np.ndarray:
    """(W,) True where a window [t_start, t_end] comes within `margin_s` of a suspect interval."""
    hit = np.zeros(len(starts), dtype=bool)
    if not len(starts):
        return hit
    t0 = run.t[starts]
    t1 = run.t[np.minimum(starts + length - 1, len(run) - 1)]
    for a, b in run.suspect:
        hit |= (t1 >= a - margin_s) & (t0 <= b + margin_s)
    return hit


def stack_windows(run: Run, starts: np.ndarray, length: int, dtype=torch.float64,
                  device: str | torch.device = "cpu") -> tuple[torch.Tensor, torch.Tensor]:
    """States (length, W, 6) and inputs (length, W, 4) of the windows at `starts`."""
    idx = starts[None, :] + np.arange(length)[:, None]  # (length, W)
    states = torch.as_tensor(run.states[idx], dtype=dtype, device=device)
    inputs = torch.as_tensor(run.inputs[idx], dtype=dtype, device=device)
    return states, inputs
