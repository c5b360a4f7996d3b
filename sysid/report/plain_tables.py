"""Plain tables for reports: a title, column headers and rows of text, each cell with an
optional mark ("met", "not-met", "muted"); shown as an HTML table and drawn as a figure for
the PDF."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from matplotlib.figure import Figure, FigureBase

MARK_COLOURS = {"met": "#d9f0dd", "not-met": "#f6d5d5", "muted": "#f0f0f0", "": "#ffffff"}


@dataclass
class PlainTable:
    """key (HTML anchor), title, columns, rows (text cells), marks (same shape as rows, or
    empty), note (below the table)."""

    key: str
    title: str
    columns: list[str]
    rows: list[list[str]]
    marks: list[list[str]] = field(default_factory=list)
    note: str = ""

    def mark(self, i: int, j: int) -> str:
        return self.marks[i][j] if self.marks else ""


def number(value, digits: int = 3, spread=None) -> str:
    """A cell: empty for a missing value, else `digits` significant figures, "± spread" when
    given."""
    try:
        value = float(value)
    except (TypeError, ValueError):
        return ""
    if math.isnan(value):
        return ""
    text = f"{value:.{digits}g}"
    try:
        spread = float(spread)
    except (TypeError, ValueError):
        spread = math.nan
    return text if math.isnan(spread) else f"{text} ± {spread:.2g}"


FONT_SIZE = 7.0        # pt, a table's cells at their natural width
FONT_SIZE_MIN = 4.5    # pt, the smallest a table is drawn to fit its box
WIDTH_USED = 0.94      # share of the figure's (or box's) width a table may take


def table_figure(table: PlainTable, into: FigureBase | None = None, rows_per_inch: float = 4.0) -> FigureBase:
    """The table drawn as a figure (title above, note below), for a PDF page. A table wider
    than its box (the figure, or `into`: a PDF page's content box) is drawn with a smaller
    font, its columns in proportion to their text, so that it fits the box's width."""
    height = 1.0 + (len(table.rows) + 1) / rows_per_inch
    fig = into if into is not None else Figure(figsize=(10.0, height), layout="constrained")
    ax = fig.subplots()
    ax.axis("off")
    cells = table.rows or [["" for _ in table.columns]]
    colours = [[MARK_COLOURS.get(table.mark(i, j), "#ffffff") for j in range(len(table.columns))]
               for i in range(len(cells))]
    drawn = ax.table(cellText=cells, colLabels=table.columns, cellColours=colours, loc="upper center",
                     cellLoc="right", colLoc="center")
    drawn.auto_set_font_size(False)
    drawn.set_fontsize(FONT_SIZE)
    _fit_width(drawn, fig, len(table.columns))
    ax.set_title(table.title, fontsize=10, loc="left")
    if table.note:
        fig.text(0.01, 0.005, table.note, fontsize=7, wrap=True, va="bottom")
    return fig


def _fit_width(drawn, fig: FigureBase, n_columns: int) -> None:
    """Columns at their text's width where the table fits `fig`'s width; otherwise a font
    scaled down by the overflow (not below FONT_SIZE_MIN) and each column's width, as a share
    of the axes' width, in proportion to its widest text (the axes then span the box, and the
    table with them)."""
    from matplotlib.backends.backend_agg import RendererAgg

    box = fig.bbox  # type: ignore[attr-defined]  # display units (pixels at the figure's dpi)
    renderer = RendererAgg(max(int(box.width), 1), max(int(box.height), 1), fig.figure.dpi)
    need = [0.0] * n_columns                    # axes fractions at FONT_SIZE
    for (_, j), cell in drawn.get_celld().items():
        need[j] = max(need[j], cell.get_required_width(renderer))
    width = sum(need) * drawn.axes.bbox.width   # pixels
    room = WIDTH_USED * box.width
    if width <= room:
        drawn.auto_set_column_width(list(range(n_columns)))
        return
    drawn.set_fontsize(max(FONT_SIZE * room / width, FONT_SIZE_MIN))
    for (_, j), cell in drawn.get_celld().items():
        cell.set_width(need[j] / sum(need))
