"""A log's own column names and units mapped onto sysid's channels (``[data.columns]``): the
config's side (`ColumnMap`, `parse_columns`), without numpy or pandas; a log's frame is read
through it by `sysid.data.columns.to_channels`.

sysid reads 13 channels (`CHANNELS`), in SI units: ``t`` [s], ``x``, ``y`` [m], ``u``, ``v``
(v_m at midship) [m/s], ``psi`` [rad], ``r`` [rad/s], ``n_prop`` [rps], ``delta_rudder``
[rad], ``wind_velo_true``, ``wind_velo_relative`` [m/s], ``wind_dir_true``,
``wind_dir_relative`` [rad]. By default a channel is the processed schema's column (``u_velo
[m/s]``, ...). ``[data.columns]`` names another column, and its unit, per channel::

    [data.columns]
    t = "time"                                   # a column name; unit: the "[...]" in it, else SI
    u = { column = "STW", unit = "knots" }       # a column and its unit, converted to m/s
    psi = { column = "heading", unit = "deg" }
    n_prop = { column = "shaft", unit = "rpm" }
    wind_velo_true = 0.0                         # a number: the channel is constant (SI)

Without relative-wind columns the relative wind is computed from the state and true wind.
Every error names the file, the column and the fix.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import Any, Mapping

from preprocessing.channels import PROCESSED, PROCESSED_CHANNEL
from sysid.errors import ConfigError

# channel -> the processed schema's header (the default column)
DEFAULT_COLUMNS = {channel: f"{name} [{PROCESSED[name]}]" for name, channel in PROCESSED_CHANNEL.items()}
CHANNELS = tuple(DEFAULT_COLUMNS)
RELATIVE_WIND = ("wind_velo_relative", "wind_dir_relative")

# quantity -> {unit spelling: factor to SI}
UNITS: dict[str, dict[str, float]] = {
    "time": {"s": 1.0, "sec": 1.0, "ms": 1e-3, "min": 60.0, "h": 3600.0},
    "length": {"m": 1.0, "km": 1000.0, "ft": 0.3048, "nmi": 1852.0},
    "speed": {"m/s": 1.0, "knots": 1852.0 / 3600.0, "knot": 1852.0 / 3600.0, "kn": 1852.0 / 3600.0,
              "kt": 1852.0 / 3600.0, "kts": 1852.0 / 3600.0, "km/h": 1.0 / 3.6, "ft/s": 0.3048},
    "angle": {"rad": 1.0, "deg": math.pi / 180.0, "degrees": math.pi / 180.0, "°": math.pi / 180.0},
    "angular rate": {"rad/s": 1.0, "deg/s": math.pi / 180.0, "°/s": math.pi / 180.0,
                     "deg/min": math.pi / 180.0 / 60.0, "rad/min": 1.0 / 60.0},
    "revolutions": {"rps": 1.0, "1/s": 1.0, "hz": 1.0, "rev/s": 1.0, "rpm": 1.0 / 60.0, "1/min": 1.0 / 60.0,
                    "rev/min": 1.0 / 60.0},
}
QUANTITY = {"t": "time", "x": "length", "y": "length", "u": "speed", "v": "speed", "psi": "angle",
            "r": "angular rate", "n_prop": "revolutions", "delta_rudder": "angle",
            "wind_velo_relative": "speed", "wind_dir_relative": "angle", "wind_velo_true": "speed",
            "wind_dir_true": "angle"}
SI_UNIT = {channel: PROCESSED[name] for name, channel in PROCESSED_CHANNEL.items()}
_ALIASES = {"degree": "deg", "degs": "deg", "deg/sec": "deg/s", "rad/sec": "rad/s", "m/sec": "m/s",
            "degrees/s": "deg/s", "knt": "kn"}
_BRACKET = re.compile(r"\[([^\]]+)\]\s*$")


def unit_factor(unit: str, channel: str, where: str) -> float:
    """The factor taking `unit` to the channel's SI unit, or `ConfigError` naming the units
    the channel takes."""
    quantity = QUANTITY[channel]
    factors = UNITS[quantity]
    key = unit.strip().lower()
    key = _ALIASES.get(key, key)
    if key in factors:
        return factors[key]
    other = next((q for q, table in UNITS.items() if key in table), None)
    what = f"is a unit of {other}" if other else "is not a unit sysid knows"
    raise ConfigError(f"{where}: unit {unit!r} {what}; channel {channel} is a{'n' if quantity[0] in 'aeiou' else ''} "
                      f"{quantity}: use one of {', '.join(dict.fromkeys(factors))}")


@dataclass(frozen=True)
class ColumnSpec:
    """Where one channel comes from: a column of the log in `unit`, or a constant (SI)."""

    channel: str
    column: str = ""
    unit: str = ""                 # "" : the "[unit]" in the column name, else the SI unit
    constant: float | None = None  # the channel's value everywhere [SI], instead of a column

    @property
    def factor(self) -> float:
        return unit_factor(self.resolved_unit, self.channel, f"[data.columns] {self.channel}")

    @property
    def resolved_unit(self) -> str:
        if self.unit:
            return self.unit
        found = _BRACKET.search(self.column)
        return found.group(1) if found else SI_UNIT[self.channel]

    def as_toml(self) -> Any:
        if self.constant is not None:
            return self.constant
        return {"column": self.column, "unit": self.unit} if self.unit else self.column


@dataclass(frozen=True)
class ColumnMap:
    """Channel -> `ColumnSpec` for the channels a config maps; the others keep the processed
    schema's columns (`DEFAULT_COLUMNS`). `source` names the config in error messages."""

    specs: tuple[ColumnSpec, ...] = ()
    source: str = field(default="", compare=False)

    def spec(self, channel: str) -> ColumnSpec:
        mine = next((s for s in self.specs if s.channel == channel), None)
        return mine if mine is not None else ColumnSpec(channel, DEFAULT_COLUMNS[channel])

    def as_table(self) -> dict:
        """The ``[data.columns]`` table this map was read from (for the resolved config)."""
        return {s.channel: s.as_toml() for s in self.specs}

    def describe(self, channel: str) -> str:
        """How a channel is read, for messages: "column 'STW' [knots]" or "constant 0"."""
        spec = self.spec(channel)
        if spec.constant is not None:
            return f"constant {spec.constant:g} {SI_UNIT[channel]}"
        named = _BRACKET.search(spec.column) and not spec.unit  # the unit is in the column's name
        return f"column {spec.column!r}" if named else f"column {spec.column!r} [{spec.resolved_unit}]"


def parse_columns(table: Any, source: str) -> ColumnMap:
    """``[data.columns]`` of a config (a TOML table) to a checked `ColumnMap`; errors name
    the config, the channel and the fix."""
    where = f"{source}: [data.columns]"
    if not isinstance(table, Mapping):
        raise ConfigError(f"{where} must be a table of channel = column (or {{ column, unit }})")
    specs = []
    for channel, value in table.items():
        if channel not in CHANNELS:
            raise ConfigError(f"{where} unknown channel {channel!r} (channels: {', '.join(CHANNELS)})")
        here = f"{where} {channel}"
        if isinstance(value, bool):
            raise ConfigError(f"{here}: expected a column name, {{ column = \"...\", unit = \"...\" }} "
                              f"or a number, got {value!r}")
        if isinstance(value, (int, float)):
            if not math.isfinite(value):
                raise ConfigError(f"{here}: a constant must be finite, got {value!r}")
            if channel == "t":
                raise ConfigError(f"{here}: time cannot be a constant; name the time column")
            specs.append(ColumnSpec(channel, constant=float(value)))
            continue
        if isinstance(value, str):
            spec = ColumnSpec(channel, value)
        elif isinstance(value, Mapping):
            unknown = set(value) - {"column", "unit"}
            if unknown:
                raise ConfigError(f"{here}: unknown key(s) {sorted(unknown)} (known: column, unit)")
            if not isinstance(value.get("column"), str) or not value["column"]:
                raise ConfigError(f"{here}: column must name a column of the log, got {value.get('column')!r}")
            unit = value.get("unit", "")
            if not isinstance(unit, str):
                raise ConfigError(f"{here}: unit must be a string such as \"{SI_UNIT[channel]}\", got {unit!r}")
            spec = ColumnSpec(channel, value["column"], unit)
        else:
            raise ConfigError(f"{here}: expected a column name or {{ column = \"...\", unit = \"...\" }}, "
                              f"got {value!r}")
        unit_factor(spec.resolved_unit, channel, here)  # a wrong unit fails now
        specs.append(spec)
    columns = [s.column for s in specs if s.constant is None]
    twice = sorted({c for c in columns if columns.count(c) > 1})
    if twice:
        raise ConfigError(f"{where} column {twice[0]!r} is mapped onto more than one channel")
    mapped = {s.channel for s in specs}
    for spec in specs:  # a column that is also the default of a channel left unmapped: read twice
        other = next((c for c, name in DEFAULT_COLUMNS.items() if name == spec.column and c not in mapped), None)
        if other is not None:
            raise ConfigError(f"{where} {spec.channel} = {spec.column!r}: that column is also read for channel "
                              f"{other} (its default column); map {other} to its own column too")
    return ColumnMap(tuple(specs), source)
