"""Preprocessing quality reports (``STEM.report.json`` of `sysid preprocess`): one table
row per file and a timeline figure of kept segments, gaps and rejected GNSS fixes."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure, FigureBase
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from sysid.report.palette import QUALITY_COLOURS

KEPT, DROPPED, SPLIT, FILLED, BASELINE, GATE = (QUALITY_COLOURS[k] for k in (
    "kept", "dropped", "split", "filled", "baseline", "gate"))
FILES_PER_FIGURE = 20


@dataclass
class QualityRow:
    """One preprocessed file: samples [-], kept/dropped segments, gaps, rejected fixes."""

    file: str
    rows: int
    missing_rows: int
    segments: int
    kept_s: float
    dropped: int
    gaps_interpolated: int
    gaps_split: int
    baseline_rejected: int
    heading_rejected: int
    fix_rejected: int
    repairs: str


def _count(value) -> int:
    return int(value.get("rejected", 0)) if isinstance(value, dict) else int(value or 0)


def quality_rows(reports: list[dict]) -> list[QualityRow]:
    rows = []
    for r in reports:
        segments = r.get("segments") or []
        rows.append(QualityRow(
            Path(str(r.get("file", "?"))).stem, int(r.get("rows", 0) or 0), int(r.get("missing_rows", 0) or 0),
            len(segments), float(sum(s.get("t_end", 0) - s.get("t_start", 0) for s in segments)),
            len(r.get("dropped_segments") or []), int(r.get("gaps_interpolated", 0) or 0),
            int(r.get("gaps_split", 0) or 0), _count(r.get("baseline")), _count(r.get("heading_gate")),
            int(r.get("fix_rejected", 0) or 0), "; ".join(map(str, r.get("repairs") or [])) or "-"))
    return rows


def quality_timeline(reports: list[dict], title: str, into: FigureBase | None = None) -> FigureBase:
    """One line per file over time [s]: kept segments (bars), dropped segments, gaps split
    or interpolated, GNSS fixes rejected by the baseline check and by the heading gate."""
    n = len(reports)
    fig = into if into is not None else Figure(figsize=(10.0, 1.6 + 0.32 * n), layout="constrained")
    ax = fig.subplots()
    for i, r in enumerate(reports):
        y = n - 1 - i
        for s in r.get("segments") or []:
            ax.barh(y, s["t_end"] - s["t_start"], left=s["t_start"], height=0.5, color=KEPT)
        for s in r.get("dropped_segments") or []:
            ax.barh(y, s["t_end"] - s["t_start"], left=s["t_start"], height=0.5, color=DROPPED)
        for g in r.get("gaps") or []:
            split = g.get("action") == "split"
            h = 0.32 if split else 0.15
            ax.plot([g["t_start"], g["t_start"]], [y - h, y + h], color=SPLIT if split else FILLED,
                    lw=1.2 if split else 0.5, alpha=1.0 if split else 0.6)
        for key, colour, dy in (("baseline", BASELINE, 0.38), ("heading_gate", GATE, -0.38)):
            times = np.asarray((r.get(key) or {}).get("rejected_t") or [], dtype=float)
            if len(times):
                ax.plot(times, np.full_like(times, y + dy), "|", color=colour, ms=4)
    ax.set_yticks(range(n), [Path(str(r.get("file", "?"))).stem for r in reversed(reports)], fontsize=7)
    ax.set_ylim(-0.8, n - 0.2)
    ax.set_xlabel("t [s]")
    ax.grid(axis="y", visible=False)
    handles = [Patch(color=KEPT, label="kept segment"), Patch(color=DROPPED, label="dropped segment"),
               Line2D([], [], color=SPLIT, label="gap: split"), Line2D([], [], color=FILLED, label="gap: interpolated"),
               Line2D([], [], color=BASELINE, marker="|", ls="", label="GNSS fix rejected (baseline)"),
               Line2D([], [], color=GATE, marker="|", ls="", label="GNSS heading rejected (gate)")]
    fig.legend(handles=handles, loc="outside lower center", ncol=3, frameon=False, fontsize=8)
    fig.suptitle(title, fontsize=10)
    return fig
