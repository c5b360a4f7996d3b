"""Preprocessing quality reports (``STEM.report.json`` of `sysid preprocess`): one table
row per file and a timeline figure of kept segments, gaps and rejected GNSS fixes."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure, FigureBase
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from preprocessing.quality import QualityReport
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


def quality_rows(reports: list[QualityReport]) -> list[QualityRow]:
    return [QualityRow(Path(r.file).stem, r.rows, r.missing_rows, len(r.segments), r.kept_s,
                       len(r.dropped_segments), r.gaps_interpolated, r.gaps_split, r.baseline.rejected,
                       r.heading_gate.rejected, r.fix_rejected, "; ".join(map(str, r.repairs)) or "-")
            for r in reports]


def quality_timeline(reports: list[QualityReport], title: str, into: FigureBase | None = None) -> FigureBase:
    """One line per file over time [s]: kept segments (bars), dropped segments, gaps split
    or interpolated, GNSS fixes rejected by the baseline check and by the heading gate."""
    n = len(reports)
    fig = into if into is not None else Figure(figsize=(10.0, 1.6 + 0.32 * n), layout="constrained")
    ax = fig.subplots()
    for i, r in enumerate(reports):
        y = n - 1 - i
        for s in r.segments:
            ax.barh(y, s.t_end - s.t_start, left=s.t_start, height=0.5, color=KEPT)
        for d in r.dropped_segments:
            ax.barh(y, d.t_end - d.t_start, left=d.t_start, height=0.5, color=DROPPED)
        for g in r.gaps:
            split = g.action == "split"
            h = 0.32 if split else 0.15
            ax.plot([g.t_start, g.t_start], [y - h, y + h], color=SPLIT if split else FILLED,
                    lw=1.2 if split else 0.5, alpha=1.0 if split else 0.6)
        for rejections, colour, dy in ((r.baseline, BASELINE, 0.38), (r.heading_gate, GATE, -0.38)):
            times = np.asarray(rejections.rejected_t, dtype=float)
            if len(times):
                ax.plot(times, np.full_like(times, y + dy), "|", color=colour, ms=4)
    ax.set_yticks(range(n), [Path(r.file).stem for r in reversed(reports)], fontsize=7)
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
