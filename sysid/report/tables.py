"""RMSE tables in the layout of the paper's Tables 7 and 8, ours beside the paper's.

A reproduction gives one table per horizon (rows: scenario x model; column groups: data
sets); a single run gives one table (rows: scenarios; column groups: horizons). Every cell
holds our RMSE, the paper's and the change in percent; within a scenario the lowest RMSE
of each column is marked best.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from pathlib import Path

from sysid.protocol.paper import SCENARIO_ORDER, comparison_table, model_label, paper_rmse, run_label, scenario_key
from sysid.report.palette import model_colour
from sysid.data.display_units import DisplayUnits
from sysid.evaluation.judgement import interval_text, place_names
from sysid.evaluation.verdict import BaselineVerdict as Verdict, percent_text
from sysid.report.source import ReportSource, RunRecord

COMPONENTS = ("u", "v_m", "r")


def format_rmse(value: float | None) -> str:
    """Our RMSE as printed in every table (5 decimals)."""
    return "-" if value is None or not math.isfinite(value) else f"{value:.5f}"


def format_paper(value: float | None) -> str:
    return "-" if value is None else f"{value:.4f}"


@dataclass
class Cell:
    """One RMSE: ours and the paper's [m/s or rad/s]."""

    ours: float | None
    paper: float | None
    best: bool = False
    spread: float | None = None   # std over seeds (a seed group's cell)

    @property
    def change_pct(self) -> float | None:
        """(ours - paper) / paper in percent; negative is better than the paper."""
        if self.ours is None or self.paper is None or not math.isfinite(self.ours) or self.paper == 0:
            return None
        return 100.0 * (self.ours - self.paper) / self.paper

    @property
    def beats_paper(self) -> bool:
        return self.change_pct is not None and self.change_pct < 0

    @property
    def ours_text(self) -> str:
        if self.spread is not None and math.isfinite(self.spread) and self.ours is not None:
            return f"{self.ours:.4f}±{self.spread:.4f}"
        return format_rmse(self.ours)

    @property
    def paper_text(self) -> str:
        return format_paper(self.paper)

    @property
    def change_text(self) -> str:
        c = self.change_pct
        return "" if c is None else f"{c:+.0f}%"


@dataclass
class TableRow:
    scenario: str
    model: str
    colour: str
    cells: list[Cell]


@dataclass
class RmseTable:
    """title; groups : column-group labels (each has u, v_m, r); rows in scenario blocks."""

    key: str
    title: str
    groups: list[str]
    rows: list[TableRow] = field(default_factory=list)
    units: str = "u, v_m in m/s, r in rad/s"   # the units of the cells, said under the table

    @property
    def has_best(self) -> bool:
        return any(c.best for row in self.rows for c in row.cells)

    @property
    def has_paper(self) -> bool:
        """Any cell with the paper's value (a paper protocol)."""
        return any(c.paper is not None for row in self.rows for c in row.cells)

    @property
    def wins(self) -> tuple[int, int]:
        """(cells better than the paper, cells with a paper value)."""
        cells = [c for row in self.rows for c in row.cells if c.change_pct is not None]
        return sum(c.beats_paper for c in cells), len(cells)


def scenario_files(run: RunRecord) -> dict[str, str]:
    """Row label per metrics file: the scenario, or "scenario: file" when it has several files."""
    frame = run.metrics
    labels = {}
    counts = frame.groupby(frame["scenario"].astype(str))["file"].nunique()
    for scenario, file in zip(frame["scenario"].astype(str), frame["file"].astype(str)):
        stem = Path(file).stem
        labels[stem] = scenario if counts[scenario] == 1 else f"{scenario}: {stem}"
    return labels


def run_rmse(run: RunRecord) -> dict[tuple[str, int], tuple[float, float, float]]:
    """(row label, horizon [s]) -> (u, v_m, r) RMSE from metrics.csv."""
    labels = scenario_files(run)
    out = {}
    for row in run.metrics.itertuples(index=False):
        key = (labels[Path(str(row.file)).stem], int(round(row.horizon_s)))
        out[key] = (float(row.rmse_u), float(row.rmse_v), float(row.rmse_r))
    return out


def _scenario_order(labels) -> list[str]:
    """The paper's order first (any spelling), then the others (held-out files) as found."""
    labels = list(dict.fromkeys(labels))
    rank = {scenario_key(s): i for i, s in enumerate(SCENARIO_ORDER)}
    return sorted(labels, key=lambda s: rank.get(scenario_key(s), len(rank)))


def _paper_scenario(label: str) -> str:
    return label.split(":")[0]


def _mark_best(rows: list[TableRow]) -> None:
    by_scenario: dict[str, list[TableRow]] = {}
    for row in rows:
        by_scenario.setdefault(row.scenario, []).append(row)
    for block in by_scenario.values():
        if len(block) < 2:
            continue
        for j in range(len(block[0].cells)):
            values = [(r.cells[j].ours, r) for r in block
                      if r.cells[j].ours is not None and math.isfinite(r.cells[j].ours)]
            if len(values) > 1:
                best = min(v for v, _ in values)
                for v, r in values:
                    r.cells[j].best = v == best


def reproduction_tables(source: ReportSource) -> list[RmseTable]:
    """Tables 7 and 8 (one per horizon) from `sysid.protocol.paper.comparison_table`: rows scenario x
    model, column groups the data sets."""
    runs = source.runs
    datasets = tuple(sorted({r.dataset for r in runs if r.dataset not in ("-", "files")})) or ("D1", "D2")
    relabelled = []
    for run in runs:
        labels = scenario_files(run)
        metrics = run.metrics.assign(scenario=run.metrics["file"].astype(str).map(lambda f: labels[Path(f).stem]))  # noqa: B023
        relabelled.append((run.name, run.model, run.dataset, metrics))
    long = comparison_table(relabelled, datasets)
    colour = {}
    for run in runs:
        colour.setdefault(model_label(run.name, run.model, run.dataset), model_colour(run.name, run.model, run.dataset))
    tables = []
    for number, horizon in enumerate(sorted(long.horizon_s.unique())):
        horizon = int(horizon)
        paper_no = {30: "7", 100: "8"}.get(horizon)
        title = (f"Table {paper_no}" if paper_no else f"Table {7 + number}") + \
            f": RMSE of {horizon} s predictions (u, v_m [m/s]; r [rad/s])"
        table = RmseTable(f"table_{horizon}s", title, list(datasets))
        at = long[long.horizon_s == horizon]
        for (scenario, model), block in at.groupby(["scenario", "model"], sort=False):
            cells = []
            for dataset in datasets:
                row = block[block.dataset == dataset]
                for c in ("u", "v", "r"):
                    if row.empty:
                        cells.append(Cell(None, None))
                        continue
                    paper = float(row[f"paper_{c}"].iloc[0])
                    spread = float(row[f"std_{c}"].iloc[0])
                    cells.append(Cell(float(row[f"rmse_{c}"].iloc[0]), None if math.isnan(paper) else paper,
                                      spread=None if math.isnan(spread) else spread))
            table.rows.append(TableRow(scenario, model, colour.get(model, "#000000"), cells))
        _mark_best(table.rows)
        tables.append(table)
    return tables


def run_table(run: RunRecord, paper: bool = True) -> RmseTable:
    """One run: rows the scenarios (test logs), the run and its physics baselines in each;
    column groups the horizons. The paper's values only for a paper protocol (`paper`)."""
    rmse = run_rmse(run)
    baselines = _baseline_rmse(run)
    horizons = run.horizons()
    label = run_label(run.name, run.model, run.dataset)
    units = DisplayUnits() if paper else DisplayUnits.of_config(run.config)  # the paper's tables are SI

    def shown(values, i):
        return units.value(COMPONENTS[i], values[i]) if values else None

    table = RmseTable("table_run", f"RMSE of {label}" + (" beside its physics baselines" if baselines else "")
                      + f" (u [{units.unit('u')}], v_m [{units.unit('v_m')}], r [{units.unit('r')}])",
                      [f"{h} s" for h in horizons],
                      units=f"u in {units.unit('u')}, v_m in {units.unit('v_m')}, r in {units.unit('r')}")
    for scenario in _scenario_order(s for s, _ in rmse):
        cells = []
        for horizon in horizons:
            values = rmse.get((scenario, horizon))
            ref = paper_rmse(_paper_scenario(scenario), run.model, run.dataset, horizon) if paper else None
            for i in range(3):
                cells.append(Cell(shown(values, i), ref[i] if ref else None))
        table.rows.append(TableRow(scenario, label, model_colour(run.name, run.model, run.dataset), cells))
        for j, (baseline, values_of) in enumerate(baselines.items()):
            cells = []
            for horizon in horizons:
                values = values_of.get((scenario, horizon))
                cells += [Cell(shown(values, i), None) for i in range(3)]
            table.rows.append(TableRow(scenario, baseline, BASELINE_COLOURS[j % len(BASELINE_COLOURS)], cells))
    _mark_best(table.rows)
    return table


BASELINE_COLOURS = ("#7f7f7f", "#b0b0b0")   # the physics baselines' rows (grey)


def _baseline_rmse(run: RunRecord) -> dict[str, dict[tuple[str, int], tuple[float, float, float]]]:
    """baseline label -> (row label, horizon [s]) -> (u, v_m, r) RMSE, from baseline_metrics.csv."""
    frame = run.baseline_metrics
    if frame is None or not len(frame):
        return {}
    labels = scenario_files(run)
    out: dict = {}
    for row in frame.itertuples(index=False):
        key = (labels.get(Path(str(row.file)).stem, Path(str(row.file)).stem), int(round(row.horizon_s)))
        out.setdefault(str(row.baseline), {})[key] = (float(row.rmse_u), float(row.rmse_v), float(row.rmse_r))
    return out


@dataclass
class VerdictTable:
    """Page 1: the verdict sentence and its evidence, cell by cell: per split, log, horizon
    and channel the windows, the model's RMSE, each baseline's, the change with its interval
    and the rule's decision. header and rows are text cells, the first `key_columns` naming
    the cell; `beats` False marks a warning."""

    statement: str
    beats: bool
    header: list[str]
    rows: list[list[str]]
    losses: str = ""   # "val_loss_multistep: hybrid 0.05772, MMG (ship file) 0.05870"
    key_columns: int = 4


def _judged_rows(verdict: Verdict, split: str, judgements: dict, units: DisplayUnits) -> list[list[str]]:
    first = next(iter(judgements.values()))
    names = place_names(first.cells)
    rows = []
    for i, cell in enumerate(first.cells):
        label = split + (" (decides)" if split == verdict.decided_on else "")
        shown = functools.partial(units.value, cell.channel)
        std = verdict.member_spread(split, cell.log, cell.horizon_s, cell.channel)
        spread = f" ± {shown(std):.5f}" if std is not None and math.isfinite(std) else ""
        row = [label, names[cell.log], f"{cell.horizon_s:g} s",
               f"{cell.channel} [{units.unit(cell.channel)}]", str(cell.n_windows),
               format_rmse(shown(cell.model_rmse)) + spread]
        for b in verdict.baselines:
            c = judgements[b].cells[i] if b in judgements else None
            if c is None:
                row += ["-", "-", "-"]
                continue
            interval = f" ({interval_text(c.change_low, c.change_high)})" if math.isfinite(c.change_low) else ""
            row += [format_rmse(shown(c.baseline_rmse)), percent_text(c.change) + interval, c.decision.value]
        rows.append(row)
    return rows


def verdict_table(verdict: Verdict, model: str, units: DisplayUnits | None = None) -> VerdictTable:
    """The first page's table of a `BaselineVerdict`: every judged cell (deciding split
    first) with its windows, the RMSE of the model (± its std over seeds) and of each
    baseline, the model's change against it with its interval and the decision; a run
    written before the rule shows its pooled cells. RMSE in `units` (the user's
    ``[data.columns]`` units; None: SI)."""
    units = units if units is not None else DisplayUnits()
    header = ["Split", "Log", "Horizon", "Channel", "Windows", f"{model} RMSE"]
    conf = next((f"{100 * j.confidence:g} %" for j in verdict.judgements.values()), "95 %")
    for b in verdict.baselines:
        header += [f"{b} RMSE", f"change vs {b} ({conf} interval)", "decision"]
    rows = []
    if verdict.judgements:
        rows += _judged_rows(verdict, verdict.decided_on, verdict.judgements, units)
        if verdict.decided_on != "validation" and verdict.validation_judgements:
            rows += _judged_rows(verdict, "validation", verdict.validation_judgements, units)
    else:
        order = sorted(verdict.cells, key=lambda c: (c.split != verdict.decided_on, c.horizon_s))
        for c in order:
            shown = functools.partial(units.value, c.channel)
            spread = f" ± {shown(c.model_std):.5f}" if c.model_std is not None and math.isfinite(c.model_std) else ""
            row = [c.split + (" (decides)" if c.split == verdict.decided_on else ""), "all (pooled)",
                   f"{c.horizon_s:g} s", f"{c.channel} [{units.unit(c.channel)}]", "-",
                   format_rmse(shown(c.model)) + spread]
            for b in verdict.baselines:
                row += [format_rmse(shown(c.baselines[b])), percent_text(c.change(b)), "-"]
            rows.append(row)
    losses = ", ".join(f"{model if k == 'model' else k} {v:.5f}" for k, v in verdict.val_loss_multistep.items()
                       if math.isfinite(v))
    return VerdictTable(verdict.statement(), verdict.beats_baseline, header, rows,
                        f"val_loss_multistep (the validation loss, on the validation windows): {losses}" if losses else "")


def build_tables(source: ReportSource) -> list[RmseTable]:
    if not source.runs:
        return []
    if source.kind == "reproduction":
        return reproduction_tables(source)
    table = run_table(source.runs[0], source.paper_protocol)
    return [table] if table.rows else []   # no test logs: no RMSE table (the verdict is on validation)
