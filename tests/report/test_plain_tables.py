"""A plain table on a PDF page stays inside the page's content box: a table wider than the
box is drawn with a smaller font and proportional columns, a narrow one as it is."""
from __future__ import annotations

from functools import partial

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.table import Table

from sysid.report.pdf import figure_page
from sysid.report.plain_tables import FONT_SIZE, FONT_SIZE_MIN, PlainTable, table_figure


def _drawn(table: PlainTable):
    """The table's page drawn: (the page's content box, the table's extent, its font size [pt])."""
    size = tuple(table_figure(table).get_size_inches())
    page, box = figure_page(partial(table_figure, table), size, table.title)
    canvas = FigureCanvasAgg(page)
    canvas.draw()
    drawn = [a for ax in box.axes for a in ax.get_children() if isinstance(a, Table)][0]
    extent = drawn.get_window_extent(canvas.get_renderer())
    font = next(iter(drawn.get_celld().values())).get_text().get_fontsize()
    return box.bbox, extent, font


def _table(columns: int, text: str) -> PlainTable:
    return PlainTable("t", "a table", [f"{text} {j} [m]" for j in range(columns)],
                      [[f"{text} {i}.{j}" for j in range(columns)] for i in range(6)])


def test_a_table_wider_than_the_page_is_drawn_inside_its_content_box():
    box, extent, font = _drawn(_table(12, "turning_35_starboard"))
    assert box.x0 - 1 <= extent.x0 and extent.x1 <= box.x1 + 1, (box, extent)
    assert FONT_SIZE_MIN <= font < FONT_SIZE


def test_a_narrow_table_keeps_its_font_and_natural_columns():
    box, extent, font = _drawn(_table(3, "advance"))
    assert font == FONT_SIZE
    assert extent.width < 0.5 * box.width    # columns at their text's width, not stretched


def test_the_font_shrinks_with_the_overflow():
    fonts = [_drawn(_table(6, word))[2] for word in ("zigzag_10_10_starboard", "turning_35_starboard_long")]
    assert FONT_SIZE_MIN < fonts[1] < fonts[0] < FONT_SIZE
