"""The per-run quality report of preprocessing: what was found and decided, typed.

Built by `pipeline.Pipeline.run`, written as ``STEM.report.json`` by `writer.write_segments`,
read back with `QualityReport.from_json` (by ``sysid report`` and the CLI summary). Times
in s from the log's start; angles in rad.
"""
from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field, fields


@dataclass
class Segment:
    """A kept stretch of the log [s] and its number of output samples."""

    t_start: float
    t_end: float
    samples: int = 0

    @property
    def duration(self) -> float:
        return self.t_end - self.t_start


@dataclass
class DroppedSegment:
    """A stretch too short to keep [s], and why."""

    t_start: float
    t_end: float
    reason: str = ""


@dataclass
class Gap:
    """Missing samples of one channel [s]: interpolated, split (segment boundary) or trimmed."""

    channel: str
    t_start: float
    t_end: float
    duration_s: float = 0.0
    action: str = "split"


@dataclass
class Rejections:
    """GNSS samples rejected by a check (antenna baseline, heading gate): count, times [s]
    and the check's statistics (errors in m or rad)."""

    rejected: int = 0
    rejected_t: list[float] = field(default_factory=list)
    stats: dict = field(default_factory=dict)

    @classmethod
    def from_dict(cls, d: dict | None) -> "Rejections":
        d = dict(d or {})
        return cls(int(d.pop("rejected", 0)), list(d.pop("rejected_t", [])), d)

    def to_dict(self) -> dict:
        return {"rejected": self.rejected, "rejected_t": self.rejected_t, **self.stats}


@dataclass
class QualityReport:
    """One raw log's preprocessing: input rows, repairs, gaps, GNSS rejections, segments."""

    file: str
    settings: dict = field(default_factory=dict)
    repairs: list[str] = field(default_factory=list)
    rows: int = 0
    missing_rows: int = 0
    time_jitter_max_s: float = 0.0
    reference_latlon: list[float] | None = None
    fix_rejected: int = 0
    swapped_antennas: bool = False
    baseline: Rejections = field(default_factory=Rejections)
    heading_gate: Rejections = field(default_factory=Rejections)
    gaps: list[Gap] = field(default_factory=list)
    gaps_interpolated: int = 0
    gaps_split: int = 0
    segments: list[Segment] = field(default_factory=list)
    dropped_segments: list[DroppedSegment] = field(default_factory=list)
    fog_bias_rad_s: dict = field(default_factory=dict)   # mean, min, max [rad/s]
    outputs: list[str] = field(default_factory=list)     # file names written

    @property
    def kept_s(self) -> float:
        """Seconds of the log kept in segments."""
        return float(sum(s.duration for s in self.segments))

    @classmethod
    def from_dict(cls, d: dict) -> "QualityReport":
        known = {f.name for f in fields(cls)}
        d = {k: v for k, v in d.items() if k in known}
        return cls(**{**d,
                      "baseline": Rejections.from_dict(d.get("baseline")),
                      "heading_gate": Rejections.from_dict(d.get("heading_gate")),
                      "gaps": [Gap(**g) for g in d.get("gaps") or []],
                      "segments": [Segment(**s) for s in d.get("segments") or []],
                      "dropped_segments": [DroppedSegment(**s) for s in d.get("dropped_segments") or []]})

    def to_dict(self) -> dict:
        d = asdict(self)
        d["baseline"], d["heading_gate"] = self.baseline.to_dict(), self.heading_gate.to_dict()
        return d

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=1, default=float)

    @classmethod
    def from_json(cls, text: str) -> "QualityReport":
        return cls.from_dict(json.loads(text))
