"""A log's columns read as sysid's channels (`to_channels`) through the config's
`sysid.config.column_map.ColumnMap` (``[data.columns]``; its names stay importable here)."""
from __future__ import annotations

import numpy as np
import pandas as pd

from sysid.config.column_map import (CHANNELS, DEFAULT_COLUMNS, QUANTITY, RELATIVE_WIND, SI_UNIT,  # noqa: F401
                                     UNITS, ColumnMap, ColumnSpec, parse_columns, unit_factor)
from sysid.data.csvfiles import row_name
from sysid.errors import ConfigError, DataError


def to_channels(columns: ColumnMap, frame: pd.DataFrame, path) -> pd.DataFrame:
    """The log's columns (`frame`, read from `path`) as sysid's channels by `columns`
    (`CHANNELS` order, SI units, float).

    The relative wind, when neither mapped nor present, is NaN here (`read_run`
    computes it from the state). Raises `DataError` naming the file, the column and
    the fix."""
    out, missing, text_cells, unknown_units = {}, [], [], []
    mapped = {s.channel for s in columns.specs}
    where = f" ([data.columns] in {columns.source})" if columns.source and columns.specs else ""
    for channel in CHANNELS:
        spec = columns.spec(channel)
        if spec.constant is not None:
            out[channel] = np.full(len(frame), float(spec.constant))
            continue
        if spec.column not in frame.columns:
            if channel in RELATIVE_WIND and channel not in mapped:  # computed by read_run
                out[channel] = np.full(len(frame), np.nan)
            else:
                missing.append(spec)
            continue
        column = frame[spec.column]
        if _is_plain_number(column):  # floats or integers: numbers as they are, no text cell
            values = column
        else:
            values = _numbers(column, channel, path)
            text = column.notna() & values.isna()
            if text.any():   # every such column is named in one error below
                row = int(np.argmax(text.to_numpy()))
                text_cells.append(f"column {spec.column!r} (channel {channel}) holds "
                                  f"{column.iloc[row]!r} at {row_name(path, row)}")
                continue
        try:
            factor = spec.factor
        except ConfigError as exc:  # a unit in a header the config did not name
            unknown_units.append(f"column {spec.column!r}: {str(exc).split(': ', 1)[-1]}")
            continue
        out[channel] = values.to_numpy(dtype=float) * factor
    if missing:
        first = missing[0]
        fix = (f"correct {first.channel} in [data.columns]{where}" if first.channel in mapped else
               f"map the file's columns onto the channels in the config's [data.columns], e.g. "
               f"{first.channel} = {{ column = \"...\", unit = \"{SI_UNIT[first.channel]}\" }}")
        listed = ", ".join(f"{s.column!r} for channel {s.channel}" for s in missing)
        raise DataError(f"{path}: no column {listed} (the file has "
                        f"{', '.join(map(repr, frame.columns[:16]))}{', ...' if len(frame.columns) > 16 else ''})"
                        f"; {fix}")
    if text_cells:
        raise DataError(f"{path}: not a number in {len(text_cells)} column(s): {'; '.join(text_cells)}; "
                        "write numbers only (no units or text in the cells)")
    if unknown_units:
        raise DataError(f"{path}: {'; '.join(unknown_units)}; set the unit(s) in [data.columns]{where}")
    return pd.DataFrame(out, index=frame.index)


def _is_plain_number(column: pd.Series) -> bool:
    """A column of float or integer numbers (NumPy dtypes, not boolean): `_numbers` would
    return it unchanged."""
    return column.dtype.kind in "fiu"


def _numbers(column: pd.Series, channel: str, path) -> pd.Series:
    """A log's column as numbers: a time column of timestamps or durations in seconds (from
    the first sample); a boolean or date column for any other channel is a `DataError`."""
    if channel == "t" and pd.api.types.is_datetime64_any_dtype(column):
        return (column - column.iloc[0]).dt.total_seconds()
    if channel == "t" and pd.api.types.is_timedelta64_dtype(column):
        return column.dt.total_seconds()
    kind = ("true/false values" if pd.api.types.is_bool_dtype(column)
            or (column.dtype == object and column.map(lambda v: isinstance(v, (bool, np.bool_))).any())
            else "dates or durations" if pd.api.types.is_datetime64_any_dtype(column)
            or pd.api.types.is_timedelta64_dtype(column) else None)
    if kind is not None:
        raise DataError(f"{path}: column {column.name!r} (channel {channel}) holds {kind}, not numbers "
                        f"in {SI_UNIT[channel]}; map channel {channel} to a numeric column in [data.columns]")
    return pd.to_numeric(column, errors="coerce")
