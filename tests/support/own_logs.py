"""A user's own logs made from the real dataset: a processed FRT-DS-ESSO file rewritten under
a new name with the user's column names and units (knots, degrees, rpm, deg/s), no relative
wind, as CSV or Parquet; and the ``[data.columns]`` table that maps them back."""
from __future__ import annotations

import math
from pathlib import Path

import pandas as pd

from sysid.data.columns import DEFAULT_COLUMNS

KNOT = 1852.0 / 3600.0   # m/s
DEG = math.pi / 180.0    # rad
# channel -> (the user's column, its unit, SI value per unit)
OWN_COLUMNS = {
    "t": ("time", "s", 1.0),
    "x": ("north [m]", "", 1.0),           # the unit in the header
    "y": ("east", "m", 1.0),
    "u": ("surge speed", "knots", KNOT),
    "v": ("sway speed", "kn", KNOT),
    "psi": ("heading", "deg", DEG),
    "r": ("yaw rate", "deg/s", DEG),
    "n_prop": ("shaft", "rpm", 1.0 / 60.0),
    "delta_rudder": ("rudder", "deg", DEG),
    "wind_velo_true": ("true wind speed", "knots", KNOT),
    "wind_dir_true": ("true wind from", "deg", DEG),
}


def write_own_log(source: Path, target: Path) -> Path:
    """`source` (a processed dataset file) as the user's log `target` (.csv or .parquet)."""
    original = pd.read_csv(source)
    own = pd.DataFrame({column: original[DEFAULT_COLUMNS[channel]] / per_unit
                        for channel, (column, _, per_unit) in OWN_COLUMNS.items()})
    own = own[list(own.columns)[::-1]]   # another column order too
    if target.suffix == ".parquet":
        own.to_parquet(target, index=False)
    else:
        own.to_csv(target, index=False)
    return target


def columns_table() -> str:
    """The ``[data.columns]`` TOML table for `OWN_COLUMNS`."""
    lines = ["[data.columns]"]
    for channel, (column, unit, _) in OWN_COLUMNS.items():
        lines.append(f'{channel} = {{ column = "{column}", unit = "{unit}" }}' if unit else f'{channel} = "{column}"')
    return "\n".join(lines) + "\n"
