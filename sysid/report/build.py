"""`build_report`: a run or reproduction directory to ``report.html`` and ``report.pdf``.

Both files hold the same content (summary, methods, RMSE tables, figures) and are written
atomically. Each figure is drawn (Agg, no pyplot) as inline SVG for the page and again into
its PDF page; with `workers` > 1 the SVGs are drawn in worker processes while this process
draws the PDF's pages (the same calls: the files do not depend on `workers`).
"""
from __future__ import annotations

import contextlib
import datetime as _dt
import multiprocessing
import os
import signal
import threading
import time
from concurrent.futures import Future, ProcessPoolExecutor
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any, Callable, Iterator

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
from sysid.workers import _ignore_interrupts, _stop  # noqa: E402

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


def _verdict_label(source, verdict) -> str:
    """The judged model's name in the verdict table: its run's label, or for a verdict over
    several seeds the model's kind with their number ("Hybrid (2 seeds)"): the cells hold
    every seed's windows, not the first seed's alone."""
    run = source.runs[0]
    if verdict.seeds > 1:   # the kind's label, named as a run of that name is ("Hybrid D2")
        return f"{run_label(run.model, run.model, run.dataset)} ({verdict.seeds} seeds)"
    return run_label(run.name, run.model, run.dataset)


def ship_size(source: ReportSource) -> tuple[float, float] | None:
    """(L_pp, B) [m] of the runs' ship (the first run's copy of its ship file, else the file
    its summary names), or None when its definition cannot be loaded."""
    from sysid.mmg.ship import load_ship
    run = next((r for r in source.runs if r.summary.ship), None)
    if run is None:
        return None
    copy = run.run_dir.ship_copy(run.summary.ship)
    try:
        ship = load_ship(copy if copy.is_file() else run.summary.ship)
        return float(ship["L_pp"]), float(ship["B"])
    except Exception:  # noqa: BLE001 - an unknown ship only costs the outlines
        return None


def _placeholder(message: str, into=None):
    from matplotlib.figure import Figure
    fig = into if into is not None else Figure(figsize=(10.0, 2.0), layout="constrained")
    fig.text(0.5, 0.5, message, ha="center", va="center", wrap=True)
    return fig


def build_report(source_dir: str | os.PathLike, out_dir: str | os.PathLike,
                 progress: Callable[[str], None] | None = None, sweeps=(), workers: int = 1) -> ReportPaths:
    """Write ``out_dir/report.html`` and ``out_dir/report.pdf`` for a run directory or a
    reproduction directory (`sysid.runs.layout`); `sweeps`: sweep directories whose validation
    landscape and chosen configuration the report shows beside. `workers` > 1: the HTML's
    figures are drawn in ``workers - 1`` processes beside this one's PDF pages (the same
    files). Raises `CheckpointError` naming the missing or corrupt file."""
    started = time.perf_counter()
    # the workers start first: their imports and reading overlap this process's text and table pages
    with _SvgDrawers(workers - 1, str(source_dir), tuple(str(s) for s in sweeps)) as drawers:
        return _build(source_dir, out_dir, progress, sweeps, drawers, started)


def _build(source_dir, out_dir, progress, sweeps, drawers: "_SvgDrawers", started: float) -> ReportPaths:
    """`build_report`'s work, the HTML's figures from `drawers`."""
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
    first = verdict_table(verdict, _verdict_label(source, verdict),
                          DisplayUnits.of_config(source.runs[0].config)) if verdict is not None else None
    built = _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    title = f"sysid accuracy report: {source.title}"

    quality = quality_rows(source.quality)
    text_pages = paginate(text_lines(text_blocks(title, summary, rows, methods, quality, notes, first, settings, chosen)))
    split_tables = [(t, table_pages(t)) for t in tables]
    total = len(text_pages) + sum(len(p) for _, p in split_tables) + len(plain) + len(plan.figures)

    pdf_path = out_dir / "report.pdf"
    drawn = drawers.drawn(len(plan.figures))  # drawn while this process writes the text and table pages
    with rc_context(STYLE), pdf_style(), atomic_path(pdf_path, ".pdf") as tmp:  # type: ignore[arg-type]
        pdf = PdfReport(tmp, title, total)
        _add_pages(pdf, text_pages, split_tables, plain)
        say(f"tables: {len(tables) + len(plain)}; drawing {len(plan.figures)} figures"
            + (f" (their SVGs in {drawers.count} worker process{'es' if drawers.count > 1 else ''})"
               if drawn else ""))
        html_figures = _add_figures(pdf, plan.figures, notes, say, drawn)
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


@dataclass(frozen=True)
class DrawnFigure:
    """A figure drawn for the HTML page: its inline SVG, its own size (w, h) [in] and the
    failure message when its factory raised (then the SVG is of the placeholder)."""

    svg: str
    size: tuple[float, float]
    failure: str | None


def _drawn(spec: FigureSpec, number: int) -> DrawnFigure:
    """Figure `number` of the plan drawn as SVG; a figure that fails is a placeholder naming
    the failure: one bad figure must not cost the report."""
    failure = None
    try:
        fig = spec.factory()
    except Exception as exc:  # noqa: BLE001 - one bad figure must not cost the report
        failure = f"{spec.title}: failed ({type(exc).__name__}: {exc})"
        fig = _placeholder(failure)
    w, h = fig.get_size_inches()  # type: ignore[attr-defined]
    return DrawnFigure(figure_svg(fig, f"f{number}"), (float(w), float(h)), failure)  # type: ignore[arg-type]


_PLANS: dict[tuple, list[FigureSpec]] = {}   # a worker process's figure plans, by (source, sweeps)


def _planned(key: tuple[str, tuple[str, ...]]) -> int:
    """In a worker process: the figure plan of (source directory, sweeps), as `build_report`
    makes it, kept for `_drawn_svg`; its number of figures."""
    if key not in _PLANS:
        source = read_source(key[0], [Path(s) for s in key[1]])
        _PLANS[key] = figure_plan(source, ship_size(source)).figures
    return len(_PLANS[key])


def _drawn_svg(item: tuple[str, tuple[str, ...], int]) -> DrawnFigure:
    """In a worker process: figure `number` of the report of (source directory, sweeps,
    number), from the plan `build_report` makes of the same directory, in its style."""
    path, sweeps, number = item
    _planned((path, sweeps))
    with rc_context(STYLE), pdf_style():  # type: ignore[arg-type]
        return _drawn(_PLANS[(path, sweeps)][number - 1], number)


class _SvgDrawers:
    """`count` worker processes drawing a report's HTML figures (`_drawn_svg`; none: `drawn`
    is empty and the figures are drawn in the caller). A context manager: entering starts a
    worker reading the source and planning its figures; leaving by an error or Ctrl-C stops
    the workers and waits until they have exited (they ignore SIGINT, as `sysid.workers`)."""

    def __init__(self, count: int, source: str, sweeps: tuple[str, ...]):
        self.count, self.key = max(0, count), (source, sweeps)
        self.pool: ProcessPoolExecutor | None = None

    def __enter__(self) -> "_SvgDrawers":
        if self.count:
            with self._interrupts_blocked():
                self.pool = ProcessPoolExecutor(max_workers=self.count, mp_context=multiprocessing.get_context("spawn"),
                                                initializer=_ignore_interrupts)
                self.pool.submit(_planned, self.key)  # starts a worker: its imports, the source read, the plan
        return self

    def drawn(self, figures: int) -> dict[int, Future]:
        """Figure number (1 .. `figures`) -> the future of its `DrawnFigure`; {} without workers."""
        if self.pool is None or figures < 2:
            return {}
        with self._interrupts_blocked():  # a worker started now starts with SIGINT blocked, too
            return {n: self.pool.submit(_drawn_svg, (*self.key, n)) for n in range(1, figures + 1)}

    def __exit__(self, kind, value, traceback) -> None:
        if self.pool is not None:
            if kind is not None:
                _stop(self.pool)
            self.pool.shutdown(wait=True, cancel_futures=True)
            self.pool = None

    @staticmethod
    @contextlib.contextmanager
    def _interrupts_blocked() -> Iterator[None]:
        blocking = threading.current_thread() is threading.main_thread() and hasattr(signal, "pthread_sigmask")
        if blocking:
            signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        try:
            yield
        finally:
            if blocking:
                signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


def _add_figures(pdf: PdfReport, figures: list[FigureSpec], notes: list[str], say: Callable[[str], None],
                 drawn_in_workers: dict[int, Future] | None = None) -> list[HtmlFigure]:
    """Draw every figure of the plan into `pdf`; the HTML's figures (`_drawn` of each number:
    from the workers' futures when given, else drawn here). A figure that fails is a
    placeholder naming the failure, noted in `notes`."""
    html_figures: list[HtmlFigure] = []
    for number, spec in enumerate(figures, 1):
        drawn = drawn_in_workers[number].result() if drawn_in_workers else _drawn(spec, number)
        draw = spec.factory
        if drawn.failure is not None:
            notes.append(drawn.failure)
            draw = lambda into=None, m=drawn.failure: _placeholder(m, into)  # noqa: E731
        html_figures.append(HtmlFigure(number, spec.key, spec.section, spec.title, spec.caption, drawn.svg))
        pdf.add_figure(draw, drawn.size, f"Figure {number}. {spec.title}. {spec.caption}")
        say(f"figure {number}/{len(figures)}: {spec.title}")
    return html_figures
