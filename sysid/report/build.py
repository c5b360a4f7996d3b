"""`build_report`: a run or reproduction directory to ``report.html`` and ``report.pdf``.

Both files hold the same content (summary, methods, RMSE tables, figures) and are written
atomically. Figures are drawn once each (Agg, no pyplot) and saved as inline SVG for the
page and as vector graphics into the PDF.
"""
from __future__ import annotations

import datetime as _dt
import os
import time
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any, Callable

import matplotlib

matplotlib.use("Agg")

from matplotlib import rc_context  # noqa: E402

import sysid  # noqa: E402
from sysid.store.files import atomic_path, write_text  # noqa: E402
from sysid.report.html import HtmlFigure, figure_svg, render_html  # noqa: E402
from sysid.report.methods import changed_settings, methods_paragraphs, run_rows, summary_items  # noqa: E402
from sysid.report.palette import model_colour  # noqa: E402
from sysid.report.pdf import PdfReport, paginate, pdf_style, table_pages, text_blocks, text_lines  # noqa: E402
from sysid.report.figure_plan import FigureSpec, figure_plan  # noqa: E402
from sysid.report.chosen_settings import chosen_section  # noqa: E402
from sysid.report.quality import quality_rows  # noqa: E402
from sysid.report.source import ReportSource, read_source  # noqa: E402
from sysid.protocol.paper import run_label  # noqa: E402
from sysid.data.display_units import DisplayUnits  # noqa: E402
from sysid.report.tables import build_tables, verdict_table  # noqa: E402
from sysid.report.maneuver_tables import record_plain_table  # noqa: E402
from sysid.report.plain_tables import table_figure  # noqa: E402

STYLE: dict[str, Any] = {"font.size": 9, "axes.titlesize": 9, "axes.labelsize": 9, "axes.grid": True,
         "grid.alpha": 0.3, "grid.linewidth": 0.5, "legend.fontsize": 8, "lines.linewidth": 1.2,
         "font.family": "DejaVu Sans", "axes.unicode_minus": False}


SUBTITLES = {"reproduction": "Reproduction of the paper", "run": "Identification run", "sweep": "Sweep",
             "preprocessing": "Preprocessing run"}


@dataclass
class ReportPaths:
    """What `build_report` wrote: the two files, figure count, skipped-figure notes, seconds."""

    html: Path
    pdf: Path
    n_figures: int = 0
    n_pages: int = 0
    notes: list[str] = field(default_factory=list)
    seconds: float = 0.0


def ship_size(source: ReportSource) -> tuple[float, float] | None:
    """(L_pp, B) [m] of the runs' ship, or None when its definition cannot be loaded."""
    from sysid.mmg.ship import load_ship
    name = next((r.summary.ship for r in source.runs if r.summary.ship), None)
    if not name:
        return None
    try:
        ship = load_ship(name)
        return float(ship["L_pp"]), float(ship["B"])
    except Exception:  # noqa: BLE001 - an unknown ship only costs the outlines
        return None


def _placeholder(message: str, into=None):
    from matplotlib.figure import Figure
    fig = into if into is not None else Figure(figsize=(10.0, 2.0), layout="constrained")
    fig.text(0.5, 0.5, message, ha="center", va="center", wrap=True)
    return fig


def build_report(source_dir: str | os.PathLike, out_dir: str | os.PathLike,
                 progress: Callable[[str], None] | None = None, sweeps=()) -> ReportPaths:
    """Write ``out_dir/report.html`` and ``out_dir/report.pdf`` for a run directory or a
    reproduction directory (`sysid.runs.rundir`); `sweeps`: sweep directories whose validation
    landscape and chosen configuration the report shows beside. Raises `CheckpointError`
    naming the missing or corrupt file."""
    started = time.perf_counter()
    say = progress or (lambda message: None)
    out_dir = Path(out_dir)
    source = read_source(source_dir, sweeps)
    say(f"read {source.kind} {source.path} ({len(source.runs)} run{'s' if len(source.runs) != 1 else ''})")
    size = ship_size(source)
    tables = build_tables(source)
    plain = [record_plain_table(source.maneuver_indices)] if source.maneuver_indices is not None else []
    plan = figure_plan(source, size)
    notes = list(plan.notes)
    if size is None and source.runs:
        notes.append("Ship dimensions unknown (summary.json 'ship' missing or not loadable): no outlines")
    summary = summary_items(source, size)
    rows = run_rows(source)
    methods = methods_paragraphs(source)
    settings = [(run_label(r.name, r.model, r.dataset), changed_settings(r)) for r in source.runs]
    chosen = chosen_section(source)
    verdict = source.verdict
    first = verdict_table(verdict, run_label(source.runs[0].name, source.runs[0].model, source.runs[0].dataset),
                          DisplayUnits.of_config(source.runs[0].config)) if verdict is not None else None
    built = _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    title = f"sysid accuracy report: {source.title}"

    quality = quality_rows(source.quality)
    text_pages = paginate(text_lines(text_blocks(title, summary, rows, methods, quality, notes, first, settings, chosen)))
    split_tables = [(t, table_pages(t)) for t in tables]
    total = len(text_pages) + sum(len(p) for _, p in split_tables) + len(plain) + len(plan.figures)

    pdf_path = out_dir / "report.pdf"
    with rc_context(STYLE), pdf_style(), atomic_path(pdf_path, ".pdf") as tmp:  # type: ignore[arg-type]
        pdf = PdfReport(tmp, title, total)
        _add_pages(pdf, text_pages, split_tables, plain)
        say(f"tables: {len(tables) + len(plain)}; drawing {len(plan.figures)} figures")
        html_figures = _add_figures(pdf, plan.figures, notes, say)
        n_pages = pdf.page
        pdf.close()
        # the HTML is written before the PDF is moved into place: a failure (a full disk) keeps neither
        html = render_html(
            title=title,
            subtitle=("PARTIAL " if source.missing_runs else "") + f"{SUBTITLES[source.kind]} "
                     f"- built {built}",
            summary=summary,
            runs=[{"row": row, "colour": model_colour(r.name, r.model, r.dataset, i)}
                  for i, (row, r) in enumerate(zip(rows, source.runs))],
            methods=methods, tables=tables, plain_tables=plain, figures=html_figures, notes=notes, quality=quality,
            verdict=first, settings=settings, chosen=chosen,
            version=sysid.__version__, source=str(source.path), built=built)
        html_path = write_text(html, out_dir / "report.html")
    return ReportPaths(html_path, pdf_path, len(html_figures), n_pages, notes,
                       time.perf_counter() - started)


def _add_pages(pdf: PdfReport, text_pages, split_tables, plain) -> None:
    """The text pages, every table (split over pages as `table_pages` says) and the plain
    tables into `pdf`."""
    for page in text_pages:
        pdf.add_text(page)
    for table, pages in split_tables:
        for i, page_rows in enumerate(pages):
            part = f" (part {i + 1} of {len(pages)})" if len(pages) > 1 else ""
            pdf.add_table(table, page_rows, part)
    for plain_table in plain:
        pdf.add_figure(partial(table_figure, plain_table), tuple(table_figure(plain_table).get_size_inches()),  # type: ignore[attr-defined]
                       plain_table.title)


def _add_figures(pdf: PdfReport, figures: list[FigureSpec], notes: list[str], say: Callable[[str], None]) -> list[HtmlFigure]:
    """Draw every figure of the plan into `pdf`; the HTML's figures. A figure that fails is a
    placeholder naming the failure, noted in `notes`: one bad figure must not cost the report."""
    html_figures: list[HtmlFigure] = []
    for number, spec in enumerate(figures, 1):
        try:
            fig = spec.factory()
            draw = spec.factory
        except Exception as exc:  # noqa: BLE001 - one bad figure must not cost the report
            message = f"{spec.title}: failed ({type(exc).__name__}: {exc})"
            notes.append(message)
            fig = _placeholder(message)
            draw = lambda into=None, m=message: _placeholder(m, into)  # noqa: E731
        html_figures.append(HtmlFigure(number, spec.key, spec.section, spec.title, spec.caption,
                                       figure_svg(fig, f"f{number}")))  # type: ignore[arg-type]
        pdf.add_figure(draw, tuple(fig.get_size_inches()), f"Figure {number}. {spec.title}. {spec.caption}")  # type: ignore[attr-defined]
        say(f"figure {number}/{len(figures)}: {spec.title}")
    return html_figures
