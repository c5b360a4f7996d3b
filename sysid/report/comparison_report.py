"""The files of a comparison directory (``sysid compare MODEL... -o DIR``)::

    comparison.csv   `sysid.evaluation.comparison.TABLE_COLUMNS`: RMSE per log, horizon,
                     channel and model, with its number of windows, the reference's RMSE,
                     the relative change with its interval and the cell's decision
    verdicts.csv     `VERDICT_COLUMNS`: each model's verdict against its reference
    windows.csv      every window's RMSE per model and member (the verdicts' evidence)
    comparison.json  the models given, the logs, horizons, what each model is judged against
                     and every verdict (`Judgement.to_dict`)
    report.html      self-contained page: the verdicts, then one table per log, horizon
    report.pdf       and channel (the same content on A4 pages)
"""
from __future__ import annotations

import datetime as _dt
import json
import math
from functools import partial
from pathlib import Path
from typing import Sequence

import jinja2
from matplotlib import rc_context

import sysid
from sysid.evaluation.comparison import Comparison
from sysid.evaluation.judgement import percent_text
from sysid.report.build import STYLE
from sysid.report.pdf import PdfReport, paginate, pdf_style, text_lines
from sysid.report.plain_tables import PlainTable, number, table_figure
from sysid.store.files import atomic_path, write_csv, write_text
from sysid.store.target import RECORD_FILES, OutputKind

_ENV = jinja2.Environment(loader=jinja2.PackageLoader("sysid.report", "templates"),
                          autoescape=jinja2.select_autoescape(["html", "j2"]))
MARKS = {"better": "met", "materially worse": "not-met", "worse, within the tolerance": "not-met",
         "diverged": "not-met", "reference": "muted"}


def _interval(row) -> str:
    if not math.isfinite(row.change):
        return ""
    low, high = row.change_low, row.change_high
    bounds = f" ({percent_text(low)} to {percent_text(high)})" if math.isfinite(low) and math.isfinite(high) else ""
    return percent_text(row.change) + bounds


def cell_tables(result: Comparison) -> list[PlainTable]:
    """One `PlainTable` per log, horizon and channel: every model's RMSE (± its spread over
    seeds), its change against its reference with the interval, and the cell's decision."""
    tables = []
    for i, ((log, h, channel), block) in enumerate(result.table.groupby(["log", "horizon_s", "channel"], sort=False)):
        first = block.iloc[0]
        unit = first.unit
        rows = [[r.model, number(r.rmse, 4, r.rmse_std), r.reference or "-", _interval(r), r.decision]
                for r in block.itertuples(index=False)]
        marks = [["", "", "", "", MARKS.get(r.decision, "")] for r in block.itertuples(index=False)]
        scenario = f" ({first.scenario})" if first.scenario and first.scenario != log else ""
        tables.append(PlainTable(f"cell-{i}", f"{log}{scenario}: {channel} at {h:g} s, {first.n_windows} windows",
                                 ["model", f"RMSE [{unit}]", "against", "change (interval)", "decision"],
                                 rows, marks))
    return tables


def verdict_table(result: Comparison) -> PlainTable:
    """Each judged model's outcome, overall change with its interval and evidence."""
    frame = result.verdict_table()
    rows = [[r.model, r.reference, r.outcome.replace("_", " "), _interval(r),
             f"{r.n_logs} logs, {r.n_windows} windows, {r.n_members} member(s)"] for r in frame.itertuples(index=False)]
    marks = [["", "", "met" if r.outcome == "beats" else "not-met" if r.outcome in ("worse", "diverged") else "muted",
              "", ""] for r in frame.itertuples(index=False)]
    confidence = next(iter(result.verdicts.values())).confidence if result.verdicts else 0.95
    return PlainTable("verdicts", "Verdicts", ["model", "against", "outcome", "RMSE change (interval)", "evidence"],
                      rows, marks, note=f"Change: the geometric mean of the cells' RMSE ratios minus 1, every log, "
                                        f"horizon and channel alike; interval at {100 * confidence:g} % confidence "
                                        "(paired bootstrap over windows, logs and seeds).")


def write_comparison(out: str | Path, result: Comparison, models: Sequence[str], logs: Sequence[str],
                     report: bool = True) -> list[Path]:
    """Write the comparison's files into `out` (an existing, empty staging directory);
    the paths written."""
    out = Path(out)
    paths = [write_csv(result.table, out / "comparison.csv", float_format="%.6g"),
             write_csv(result.verdict_table(), out / "verdicts.csv", float_format="%.6g"),
             write_csv(result.window_table(), out / "windows.csv", float_format="%.6g")]
    summary = {"models": list(models), "logs": list(logs), "horizons_s": list(result.horizons),
               "against": result.against, "references": result.references,
               "verdicts": {label: j.to_dict() for label, j in result.verdicts.items()},
               "versions": {"sysid": sysid.__version__}}
    paths.append(write_text(json.dumps(summary, indent=2, allow_nan=False, default=str), out / RECORD_FILES[OutputKind.COMPARISON]))
    if report:
        paths += _write_report(out, result, models, logs)
    return paths


def _write_report(out: Path, result: Comparison, models: Sequence[str], logs: Sequence[str]) -> list[Path]:
    title = "sysid comparison"
    built = _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    against = "the first model" if result.against == "first" else "each model's physics baseline"
    items = [("Models", "; ".join(models)), ("Logs", f"{len(logs)}: " + ", ".join(Path(f).name for f in logs)),
             ("Horizons", ", ".join(f"{h:g} s" for h in result.horizons)),
             ("Judged against", against)]
    sentences = [j.sentence for j in result.verdicts.values()]
    tables = [verdict_table(result), *cell_tables(result)]
    text = paginate(text_lines([("h1", title), ("h2", "Summary")] + [("kv", k, v) for k, v in items]
                               + [("h2", "Verdicts")] + [("p", s) for s in sentences]))
    with rc_context(STYLE), pdf_style(), atomic_path(out / "report.pdf", ".pdf") as tmp:  # type: ignore[arg-type]
        pdf = PdfReport(tmp, title, len(text) + len(tables))
        for page in text:
            pdf.add_text(page)
        for table in tables:
            fig = table_figure(table)
            pdf.add_figure(partial(table_figure, table), tuple(fig.get_size_inches()), table.title)  # type: ignore[attr-defined]
        pdf.close()
    html = _ENV.get_template("maneuvers.html.j2").render(
        title=title, subtitle=f"Models side by side on the same logs - built {built}", summary=items,
        warnings=sentences, plain_tables=tables, figures=[], version=sysid.__version__,
        source=", ".join(models), built=built)
    return [write_text(html, out / "report.html"), out / "report.pdf"]
