"""The self-contained HTML page: Jinja2 template, inline CSS, figures as inline SVG."""
from __future__ import annotations

import io
import re
from dataclasses import dataclass

import jinja2
from matplotlib import rc_context
from matplotlib.figure import Figure

from sysid.report.tables import RmseTable

_ENV = jinja2.Environment(loader=jinja2.PackageLoader("sysid.report", "templates"),
                          autoescape=jinja2.select_autoescape(["html", "j2"]),
                          trim_blocks=False, lstrip_blocks=False)


@dataclass
class HtmlFigure:
    number: int
    key: str
    section: str
    title: str
    caption: str
    svg: str


def figure_svg(fig: Figure, salt: str) -> str:
    """The figure as an inline <svg> element (text kept as text, ids unique per figure,
    no XML prolog, DOCTYPE or metadata; scales to the page width)."""
    buf = io.StringIO()
    with rc_context({"svg.fonttype": "none", "svg.hashsalt": salt}):
        fig.savefig(buf, format="svg", metadata={"Date": None, "Creator": None})
    svg = buf.getvalue()
    svg = svg[svg.index("<svg"):]
    svg = re.sub(r"<metadata>.*?</metadata>", "", svg, flags=re.S)
    svg = re.sub(r'(<svg[^>]*?)\swidth="[^"]*"\sheight="[^"]*"', r"\1", svg, count=1)
    return svg


def _html_rows(table: RmseTable) -> list[dict]:
    rows, counts = [], {}
    for row in table.rows:
        counts[row.scenario] = counts.get(row.scenario, 0) + 1
    seen = set()
    for row in table.rows:
        first = row.scenario not in seen
        seen.add(row.scenario)
        rows.append({"row": row, "first": first, "span": counts[row.scenario]})
    return rows


def render_html(*, title: str, subtitle: str, summary, runs, methods, tables: list[RmseTable],
                figures: list[HtmlFigure], notes: list[str], version: str, source: str, built: str,
                quality=(), verdict=None, settings=(), plain_tables=(), chosen=None) -> str:
    """The report page as one string; `verdict` (a `VerdictTable`) comes first, `settings`
    are (run label, [(key, value, default)]) of the settings that differ from the defaults;
    `plain_tables` (`sysid.report.plain_tables.PlainTable`) follow the RMSE tables; `chosen`
    (`sysid.report.chosen_settings.ChosenSection`) is "How the settings were chosen"."""
    for table in tables:
        table.html_rows = _html_rows(table)  # type: ignore[attr-defined]
    template = _ENV.get_template("report.html.j2")
    return template.render(title=title, subtitle=subtitle, summary=summary, runs=runs, methods=methods,
                           tables=tables, figures=figures, notes=notes, version=version, source=source,
                           built=built, quality=quality, verdict=verdict, settings=settings,
                           plain_tables=plain_tables, chosen=chosen)
