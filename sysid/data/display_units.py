"""The user's units for numbers shown to them: where ``[data.columns]`` reads u, v or r in
knots, deg/s, ... the report and the printed verdict show RMSE in those units. Files
(metrics CSVs, summary.json) stay SI."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping

from sysid.data.columns import SI_UNIT, ColumnMap, unit_factor

# the verdict's and the metrics' channel names -> the [data.columns] channel they are read from
SHOWN = {"u": "u", "v_m": "v", "r": "r"}


@dataclass(frozen=True)
class DisplayUnits:
    """channel ("u", "v_m", "r") -> (unit, SI value of one unit); a channel not listed is
    shown in SI (m/s, rad/s)."""

    units: Mapping[str, tuple[str, float]] = field(default_factory=dict)

    @classmethod
    def of(cls, columns: ColumnMap | None) -> "DisplayUnits":
        """The units `columns` reads u, v and r in (SI when `columns` is None or names none)."""
        if columns is None:
            return cls()
        out = {}
        for shown, channel in SHOWN.items():
            spec = columns.spec(channel)
            if spec.constant is not None:
                continue
            unit = spec.resolved_unit
            factor = unit_factor(unit, channel, f"[data.columns] {channel}")
            if factor != 1.0:
                out[shown] = (unit, factor)
        return cls(out)

    @classmethod
    def of_config(cls, config: Mapping | None, source: str = "config") -> "DisplayUnits":
        """From a parsed config (a run's config.toml as a dict)."""
        from sysid.data.columns import parse_columns
        table = ((config or {}).get("data") or {}).get("columns")
        return cls.of(parse_columns(table, source)) if table else cls()

    @property
    def si(self) -> bool:
        return not self.units

    def unit(self, channel: str) -> str:
        """The unit `channel` is shown in ("knots", "m/s")."""
        return self.units[channel][0] if channel in self.units else SI_UNIT[SHOWN.get(channel, channel)]

    def value(self, channel: str, si: float) -> float:
        """An SI value of `channel` (an RMSE, a speed) in the shown unit."""
        return si / self.units[channel][1] if channel in self.units else si

    def cell_text(self, channel: str, horizon_s: float, model: float, baseline: float) -> str:
        """"u at 30 s: 0.0371 against 0.0329 knots" (RMSE given in SI)."""
        return (f"{channel} at {horizon_s:g} s: {self.value(channel, model):.4g} against "
                f"{self.value(channel, baseline):.4g} {self.unit(channel)}")

    def verdict_cells(self, verdict) -> str:
        """The deciding cells of a `sysid.evaluation.verdict.BaselineVerdict` against its
        first baseline, in these units, for the line after the printed verdict."""
        first = verdict.baselines[0]
        return "; ".join(self.cell_text(c.channel, c.horizon_s, c.model, c.baselines[first]) for c in verdict.deciding
                         if c.channel in self.units)
