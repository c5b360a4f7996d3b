"""The PDF: matplotlib `PdfPages`, A4 landscape pages, vector figures and text kept as
text (TrueType, so the numbers can be searched and extracted), "page n of N" on every page.

Pages: summary and methods text, one page per RMSE table (split when long), one per figure.
"""
from __future__ import annotations

import textwrap
from contextlib import AbstractContextManager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from matplotlib import rc_context
from matplotlib.backends.backend_pdf import PdfPages
from matplotlib.figure import Figure, FigureBase
from matplotlib.patches import Rectangle

from sysid.report.tables import RmseTable, VerdictTable

PAGE = (11.69, 8.27)          # in, A4 landscape
MARGIN = 0.5                  # in
LINE = 0.17                   # in, one text line at 8.5 pt
KEY_WIDTH = 3.1               # in, key column of summary lines
LINES_PER_PAGE = int((PAGE[1] - 2 * MARGIN - 0.4) / LINE)
TABLE_ROWS_PER_PAGE = 26
STYLES = {"h1": (15, "bold", 2.0), "h2": (11, "bold", 1.6), "p": (8.5, "normal", 1.0),
          "kv": (8.5, "normal", 1.0), "small": (7.5, "normal", 1.0)}
WRAP = {"h1": 90, "h2": 120, "p": 175, "kv": 105, "small": 190}


@dataclass
class TextLine:
    style: str
    text: str
    key: str = ""


def text_blocks(title: str, summary, rows, methods, quality, notes, verdict: VerdictTable | None = None,
                settings=(), chosen=None) -> list[tuple]:
    """The report's text pages as blocks ("h1"/"h2"/"p"/"small", text) or ("kv", key, value):
    the verdict (first), summary items, run rows, methods paragraphs and the settings that
    differ from the defaults ((run label, [(key, value, default)]) pairs), how the settings
    were chosen (`sysid.report.chosen_settings.ChosenSection`), preprocessing quality rows,
    figure notes."""
    blocks: list[tuple[str, ...]] = [("h1", title)]
    if verdict is not None:
        blocks += [("h2", "Verdict"), ("p", ("" if verdict.beats else "WARNING: ") + verdict.statement)]
        k = verdict.key_columns
        blocks += [("kv", ", ".join(r[:k]), " | ".join(f"{h} {v}" for h, v in zip(verdict.header[k:], r[k:])))
                   for r in verdict.rows]
        blocks += [("small", verdict.losses)] if verdict.losses else []
    blocks += [("h2", "Summary")] + [("kv", k, str(v)) for k, v in summary]
    blocks += [("h2", "Runs")] * bool(rows) + [("kv", r.label, f"{r.model}, data set {r.dataset}, epochs {r.epochs}, "
                                                f"training {r.train_time}, config {r.config_digest}, created {r.created}")
                                                for r in rows]
    blocks += [("h2", "Methods")] + [("p", p) for p in methods]
    for label, changed in settings:
        blocks += [("p", f"Settings of {label} that differ from the defaults" + (":" if changed else ": none."))]
        blocks += [("kv", key, f"{value} (default: {default})") for key, value, default in changed]
    if chosen is not None:
        blocks += [("h2", "How the settings were chosen"), ("p", chosen.note)]
        blocks += [("kv", row.label, " | ".join(f"{h}: {v}" for h, v in zip(chosen.header[1:], row.cells[1:])))
                   for row in chosen.rows]
        blocks += [("kv", f"{r.setting}", f"{r.text} [{r.runs}]") for r in chosen.reasons]
        for name, path, items in chosen.sweeps:
            blocks += [("p", f"Sweep {name} ({path}):")] + [("kv", k, str(v)) for k, v in items]
    if quality:
        blocks += [("h2", "Preprocessing quality")] + [
            ("kv", q.file, f"{q.rows} rows ({q.missing_rows} missing), {q.segments} segments ({q.kept_s:.0f} s kept, "
             f"{q.dropped} dropped), gaps {q.gaps_interpolated} interpolated / {q.gaps_split} split, GNSS rejected: "
             f"baseline {q.baseline_rejected}, heading {q.heading_rejected}, fix {q.fix_rejected}; repairs: {q.repairs}")
            for q in quality]
    if notes:
        blocks += [("h2", "Figures not drawn")] + [("small", f"- {n}") for n in notes]
    return blocks


def text_lines(blocks: list[tuple[str, str] | tuple[str, str, str]]) -> list[TextLine]:
    """Blocks (style, text) or ("kv", key, value) wrapped into lines."""
    lines: list[TextLine] = []
    for block in blocks:
        style, text = block[0], block[-1]
        key = block[1] if len(block) == 3 else ""
        wrapped = textwrap.wrap(text, WRAP[style]) or [""]
        for i, piece in enumerate(wrapped):
            lines.append(TextLine(style, piece, key if i == 0 else ""))
        if style in ("p", "h1"):
            lines.append(TextLine("p", ""))
    return lines


def paginate(lines: list[TextLine]) -> list[list[TextLine]]:
    pages, page, used = [], [], 0.0
    for line in lines:
        height = STYLES[line.style][2]
        keep = 2.0 if line.style in ("h1", "h2") else 0.0  # a heading keeps two lines with it
        if used + height + keep > LINES_PER_PAGE and page:
            pages.append(page)
            page, used = [], 0.0
        page.append(line)
        used += height
    if page:
        pages.append(page)
    return pages


def table_pages(table: RmseTable) -> list[list]:
    """The table's rows split into pages, never inside a scenario block when avoidable."""
    pages, page = [], []
    blocks: dict[str, list] = {}
    for row in table.rows:
        blocks.setdefault(row.scenario, []).append(row)
    for rows in blocks.values():
        if page and len(page) + len(rows) > TABLE_ROWS_PER_PAGE:
            pages.append(page)
            page = []
        page += rows
    if page or not pages:
        pages.append(page)
    return pages


class PdfReport:
    """Pages written in order, each stamped with the footer "title, page n of N"."""

    def __init__(self, path: Path, title: str, total_pages: int):
        self.title = title
        self.total = total_pages
        self.page = 0
        self._pdf = PdfPages(path, metadata={"Title": title, "Creator": "sysid report"})

    def _footer(self, fig: Figure) -> None:
        self.page += 1
        fig.text(1 - MARGIN / PAGE[0], 0.25 / PAGE[1], f"page {self.page} of {self.total}",
                 ha="right", va="bottom", fontsize=8, color="#444")
        fig.text(MARGIN / PAGE[0], 0.25 / PAGE[1], self.title, ha="left", va="bottom",
                 fontsize=8, color="#444")

    def _save(self, fig: Figure) -> None:
        self._footer(fig)
        self._pdf.savefig(fig)

    def add_text(self, lines: list[TextLine]) -> None:
        fig = Figure(figsize=PAGE)
        y = PAGE[1] - MARGIN
        for line in lines:
            size, weight, height = STYLES[line.style]
            y -= LINE * height
            if line.key:
                fig.text(MARGIN / PAGE[0], y / PAGE[1], line.key, fontsize=size, weight="bold")
                fig.text((MARGIN + KEY_WIDTH) / PAGE[0], y / PAGE[1], line.text, fontsize=size)
            else:
                x = MARGIN + (KEY_WIDTH if line.style == "kv" else 0.0)
                fig.text(x / PAGE[0], y / PAGE[1], line.text, fontsize=size, weight=weight)
        self._save(fig)

    def add_table(self, table: RmseTable, rows: list, part: str = "") -> None:
        """One page of an RMSE table: our value, then the paper's and the change below."""
        fig = Figure(figsize=PAGE)
        W, H = PAGE
        fig.text(MARGIN / W, (H - MARGIN - 0.1) / H, table.title + part, fontsize=11, weight="bold")
        n_cells = 3 * len(table.groups)
        x_test, x_model, x_cells = MARGIN, MARGIN + 1.55, MARGIN + 3.0
        cell_w = (W - MARGIN - x_cells) / n_cells
        row_h = min(0.34, (H - 2 * MARGIN - 1.6) / max(len(rows), 1))
        top = H - MARGIN - 0.55
        for g, group in enumerate(table.groups):
            xc = x_cells + (3 * g + 1.5) * cell_w
            fig.text(xc / W, top / H, group, ha="center", fontsize=9, weight="bold")
            for j, comp in enumerate(("u", "v_m", "r")):
                fig.text((x_cells + (3 * g + j + 0.5) * cell_w) / W, (top - 0.22) / H, comp,
                         ha="center", fontsize=8.5, weight="bold")
        fig.text(x_test / W, (top - 0.22) / H, "Test", fontsize=8.5, weight="bold")
        fig.text(x_model / W, (top - 0.22) / H, "Model", fontsize=8.5, weight="bold")
        y = top - 0.3
        fig.add_artist(Rectangle((MARGIN / W, y / H), (W - 2 * MARGIN) / W, 0.012 / H,
                                 transform=fig.transFigure, color="#555"))
        last = None
        for row in rows:
            y -= row_h
            if row.scenario != last:
                fig.add_artist(Rectangle((MARGIN / W, (y + row_h) / H), (W - 2 * MARGIN) / W, 0.006 / H,
                                         transform=fig.transFigure, color="#999"))
                fig.text(x_test / W, (y + row_h * 0.45) / H, row.scenario, fontsize=8.5, weight="bold")
                last = row.scenario
            fig.add_artist(Rectangle((x_model / W, (y + row_h * 0.38) / H), 0.12 / W, 0.12 / H,
                                     transform=fig.transFigure, facecolor=row.colour, edgecolor="#333", lw=0.5))
            fig.text((x_model + 0.18) / W, (y + row_h * 0.4) / H, row.model, fontsize=8.5)
            for j, cell in enumerate(row.cells):
                xr = x_cells + (j + 1) * cell_w - 0.08
                if cell.best:
                    fig.add_artist(Rectangle(((xr - cell_w + 0.14) / W, (y + 0.02) / H), (cell_w - 0.1) / W,
                                             (row_h - 0.04) / H, transform=fig.transFigure,
                                             facecolor="#fff3b0", edgecolor="none"))
                fig.text(xr / W, (y + row_h * 0.55) / H, cell.ours_text, ha="right", fontsize=8.5,
                         weight="bold" if cell.best else "normal")
                if cell.paper is not None:
                    colour = "#1b7a34" if cell.beats_paper else "#b02a2a"
                    fig.text(xr / W, (y + row_h * 0.15) / H, f"{cell.paper_text} {cell.change_text}",
                             ha="right", fontsize=6.5, color=colour)
        wins, total = table.wins
        said = (f"First line: our RMSE ({table.units}); second line: the paper's value and our change "
                f"(green: better than the paper). {wins} of {total} cells better than the paper."
                if table.has_paper else f"RMSE on the test logs: {table.units}.")
        fig.text(MARGIN / W, (y - 0.35) / H,
                 said + (" Bold on yellow: lowest RMSE of the test's models in that column." if table.has_best else ""),
                 fontsize=7.5, color="#333", wrap=True)
        self._save(fig)

    def add_figure(self, draw: Callable[..., FigureBase], size: tuple[float, float], caption: str) -> None:
        """A report figure on an A4 page: `draw(into=subfigure)` redraws it into the page's
        content box (page width, the aspect of its own `size` [in] kept up to the page
        height), the caption below it."""
        self._save(figure_page(draw, size, caption)[0])

    def close(self) -> None:
        self._pdf.close()


def figure_page(draw: Callable[..., FigureBase], size: tuple[float, float], caption: str) -> tuple[Figure, Any]:
    """An A4 page (`PdfReport.add_figure`) and its content box: `draw(into=box)` fills the
    box (the page's width less its margins, the aspect of `size` [in] kept up to the page
    height), the caption below it."""
    w, h = size
    content_w = PAGE[0] - 2 * MARGIN
    content_h = min(PAGE[1] - 2 * MARGIN - 0.9, content_w * h / w)
    page = Figure(figsize=PAGE, layout="constrained")
    boxes: Any = page.subfigures(3, 3, width_ratios=[MARGIN, content_w, MARGIN],
                                 height_ratios=[MARGIN, content_h, PAGE[1] - MARGIN - content_h])
    draw(into=boxes[1, 1])
    boxes[2, 1].text(0.0, 0.85, "\n".join(textwrap.wrap(caption, 170)), fontsize=8.5, va="top",
                     transform=boxes[2, 1].transSubfigure)
    return page, boxes[1, 1]


def pdf_style() -> AbstractContextManager:
    return rc_context({"pdf.fonttype": 42, "pdf.compression": 6})
