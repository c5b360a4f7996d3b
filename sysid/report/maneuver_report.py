"""The report of a maneuvers directory (``sysid maneuver MODEL -o DIR``): ``report.html``
(self-contained) and ``report.pdf`` (A4 pages) with the same content: conditions and where
each came from, the indices (± their spread over an ensemble's members or seeds), each IMO
criterion marked met or not, the kNN gate's share along each maneuver, and the figures
(tracks with the hull outline, heading and rudder, crash stop, indices against the limits);
a learned model's physics baseline beside it in every table and figure, and a table of the
two models' indices and their difference. Everything is read from the directory's files
(`sysid.maneuvers.outputs`)."""
from __future__ import annotations

import datetime as _dt
import json
import os
import time
from functools import partial
from pathlib import Path

import jinja2
import pandas as pd
from matplotlib import rc_context

import sysid
from sysid.errors import CheckpointError
from sysid.report import maneuver_figures as MF
from sysid.report.build import STYLE, ReportPaths
from sysid.report.html import HtmlFigure, figure_svg
from sysid.report.pdf import PdfReport, paginate, pdf_style, text_lines
from sysid.report.maneuver_tables import beside_plain_table, criteria_plain_table, indices_plain_table
from sysid.report.plain_tables import table_figure
from sysid.store.files import atomic_path, write_text
from sysid.store.manifest import verify_manifest
from sysid.store.target import OutputKind, record_file

_ENV = jinja2.Environment(loader=jinja2.PackageLoader("sysid.report", "templates"),
                          autoescape=jinja2.select_autoescape(["html", "j2"]))


def _read(directory: Path) -> tuple[dict, pd.DataFrame, pd.DataFrame, pd.DataFrame]:
    record = record_file(directory, OutputKind.MANEUVERS)
    if (directory / "manifest.json").is_file():  # a finished directory (inside its staging there is none yet)
        verify_manifest(directory, "maneuvers", (record.name, "indices.csv", "criteria.csv", "trajectories.csv"))
    try:
        summary = json.loads(record.read_text())
        frames = [pd.read_csv(directory / name) for name in ("indices.csv", "criteria.csv", "trajectories.csv")]
    except (OSError, ValueError) as exc:
        raise CheckpointError(f"{directory}: not a readable maneuvers directory ({exc})") from None
    return (summary, *frames)


def _summary_items(s: dict) -> list[tuple[str, str]]:
    c, src = s["conditions"], s.get("sources", {})
    scale = s.get("scale")
    lu_full = s.get("L_over_U_full_scale_s")
    items = [("Model", f"{s['model']} ({s['kind']})"), ("Ship", f"{s['ship']} ({s.get('ship_file', '')})"),
             ("L_pp, B", f"{s['L_pp_m']:g} m, {s['B_m']:g} m"),
             ("Scale (full / this L)", "not given: criteria needing full-scale L/U not assessed" if scale is None
              else f"{scale:g}"),
             ("Approach speed U0", f"{c['speed_m_s']:.4g} m/s ({src.get('speed', '')})"),
             ("Propeller revolutions", f"{c['rps']:.4g} rps ({src.get('rps', '')})"),
             ("Rudder rate", f"{c['rudder_rate_deg_s']:.3g} deg/s ({src.get('rudder_rate', '')})"),
             ("L/U0", f"{s['L_over_U_s']:.3g} s" + ("" if lu_full is None else f"; at full scale {lu_full:.3g} s")),
             ("Integration", f"{c['integrator']}, dt {c['dt_s']:g} s, {c['duration_s']:g} s after the execute"
              + (", compiled loop" if s.get("compiled") else ", eager")),
             ("Wind", "calm water" if not c["wind_speed_m_s"] else
              f"{c['wind_speed_m_s']:g} m/s from {c['wind_direction_deg']:g} deg")]
    if s.get("n_members"):
        items.append(("Spread", f"over {s['n_members']} {s.get('spread', 'members')}"))
    base = s.get("baseline")
    if base:
        left = base.get("left_out") or []
        items.append(("Physics baseline", f"{base['model']}: the MMG of {base.get('ship_file') or s['ship']}, the same "
                      "maneuvers under the same conditions, dashed in the figures"
                      + (f"; it does not run {', '.join(left)} (propeller for ahead motion only)" if left else "")))
    return items


def is_maneuvers_directory(path: str | os.PathLike) -> bool:
    """Whether `path` is the output of ``sysid maneuver`` (its manifest says so)."""
    manifest = Path(path) / "manifest.json"
    try:
        return manifest.is_file() and json.loads(manifest.read_text()).get("kind") == "maneuvers"
    except (OSError, ValueError):
        return False


def build_maneuver_report(source_dir: str | os.PathLike, out_dir: str | os.PathLike | None = None) -> ReportPaths:
    """``report.html`` and ``report.pdf`` of a maneuvers directory into `out_dir` (default:
    the directory itself)."""
    started = time.perf_counter()
    source = Path(source_dir)
    out = Path(out_dir) if out_dir is not None else source
    summary, indices, criteria, traj = _read(source)
    main, L, B = summary["model"], float(summary["L_pp_m"]), float(summary["B_m"])
    baseline = (summary.get("baseline") or {}).get("model")
    tables = [indices_plain_table(indices), criteria_plain_table(criteria)]
    if baseline is not None:
        tables[:1] = [indices_plain_table(indices, main), indices_plain_table(indices, baseline),
                      beside_plain_table(indices, main, baseline)]
    beside = f" beside {baseline} (dashed)" if baseline is not None else ""
    checks = {}
    for name in indices["maneuver"]:
        if name.startswith("zigzag"):
            checks[name] = float(name.split("_")[2])
    dashed = f"; dashed: the physics baseline {baseline}" if baseline is not None else ""
    specs = [("tracks", "Tracks", "Midship tracks of every maneuver from the execute at the origin, approach along "
              f"x0; members of the ensemble or seeds as thin lines{dashed}",
              partial(MF.tracks, traj, main, L, B, f"Tracks of {main}{beside}", baseline=baseline))]
    for kind, words, extra in (("turning", "turning circles", "speed U [m/s] on the right axis"),
                               ("zigzag", "zig-zags", "dotted: check angles")):
        if indices["maneuver"].str.startswith(kind).any():
            specs.append((kind, f"Heading and rudder, {words}",
                          f"Heading change and rudder angle over time from the execute; {extra}{dashed}",
                          partial(MF.heading_rudder, traj, main, kind, checks if kind == "zigzag" else {},
                                  f"Heading and rudder, {words} of {main}{beside}", baseline=baseline)))
    if ((indices["maneuver"] == "crash_stop") & (indices["model"] == main)).any():
        specs.append(("crash", "Crash stop", f"Surge speed and propeller revolutions over time{dashed}",
                      partial(MF.crash_stop, traj, main, f"Crash stop of {main}{beside}", baseline=baseline)))
    if criteria["met"].isin(["met", "not met"]).any():
        specs.append(("criteria", "Indices against the IMO criteria", "Each assessed index divided by its IMO limit"
                      + (", each model on its own" if baseline is not None else ""),
                      partial(MF.criteria_chart, criteria, f"IMO criteria, {main}{beside.replace(' (dashed)', '')}")))
    warnings = [f"{r.maneuver}: kNN gate off on {100 * r.gate_off_share:.1f} % of the steps: the maneuver runs "
                "mostly outside the training data" for r in indices.itertuples(index=False)
                if "gate_off_share" in indices and not pd.isna(r.gate_off_share) and r.gate_off_share > 0.5]
    title = f"sysid maneuvers report: {main}"
    built = _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    items = _summary_items(summary)
    text = paginate(text_lines([("h1", title), ("h2", "Summary")] + [("kv", k, v) for k, v in items]
                               + [("p", w) for w in warnings]))
    figures = []
    with rc_context(STYLE), pdf_style(), atomic_path(out / "report.pdf", ".pdf") as tmp:  # type: ignore[arg-type]
        pdf = PdfReport(tmp, title, len(text) + len(tables) + len(specs))
        for page in text:
            pdf.add_text(page)
        for table in tables:
            fig = table_figure(table)
            pdf.add_figure(partial(table_figure, table), tuple(fig.get_size_inches()), table.title)  # type: ignore[attr-defined]
        for number_, (key, name, caption, factory) in enumerate(specs, 1):
            fig = factory()
            figures.append(HtmlFigure(number_, key, "Figures", name, caption, figure_svg(fig, f"m{number_}")))  # type: ignore[arg-type]
            pdf.add_figure(factory, tuple(fig.get_size_inches()), f"Figure {number_}. {name}. {caption}.")  # type: ignore[attr-defined]
        pages = pdf.page
        pdf.close()
    html = _ENV.get_template("maneuvers.html.j2").render(
        title=title, subtitle=f"Standard maneuvers (IMO MSC.137(76)) - built {built}", summary=items,
        warnings=warnings, plain_tables=tables, figures=figures, version=sysid.__version__, source=str(source),
        built=built)
    html_path = write_text(html, out / "report.html")
    return ReportPaths(html_path, out / "report.pdf", len(figures), pages, [], time.perf_counter() - started)
