"""Reading a run directory or a reproduction directory (layout: `sysid.runs.rundir`).

Every file the report needs is checked when it is read; a missing or corrupt file raises
`CheckpointError` naming it, and a run or reproduction whose manifest is missing or disagrees
with its files is refused (`IncompleteOutputError`). Traces are read lazily (a full reproduction holds ~70 of them).
"""
from __future__ import annotations

import json
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from preprocessing.quality import QualityReport
from sysid.errors import CheckpointError
from sysid.config.choices import ModelKind
from sysid.config.experiment import load_experiment
from sysid.evaluation.evaluate import METRICS_COLUMNS, TRACE_COLUMNS, trace_name
from sysid.store.manifest import has_manifest, verify_manifest
from sysid.runs.rundir import read_knn_bank, verify_run_dir
from sysid.protocol.seeds import seed_metrics



def read_json(path: Path) -> dict:
    """A JSON object from `path`, or `CheckpointError` naming the file."""
    if not path.is_file():
        raise CheckpointError(f"{path}: file not found")
    try:
        data = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise CheckpointError(f"{path}: not valid JSON ({exc})") from None
    if not isinstance(data, dict):
        raise CheckpointError(f"{path}: expected a JSON object")
    return data


def _read_table(path: Path, columns: list[str], required: bool = True) -> pd.DataFrame | None:
    if not path.is_file():
        if required:
            raise CheckpointError(f"{path}: file not found")
        return None
    try:
        frame = pd.read_csv(path)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise CheckpointError(f"{path}: not a readable CSV ({exc})") from None
    missing = [c for c in columns if c not in frame.columns]
    if missing:
        raise CheckpointError(f"{path}: missing column(s) {missing}")
    return frame


@dataclass
class RunRecord:
    """One run directory: its summary, config, metrics, loss history and traces.

    metrics : METRICS_COLUMNS, RMSE in m/s (u, v_m) and rad/s (r); history : epoch-wise
    losses or None (MMG-only runs).
    """

    name: str   # the run directory's name (mmg_paper, hybrid_D2, ... in a reproduction)
    path: Path
    summary: dict
    config_text: str
    config: dict
    metrics: pd.DataFrame
    history: pd.DataFrame | None
    _traces: dict = field(default_factory=dict, repr=False)
    seeds: list["RunRecord"] = field(default_factory=list)   # a seed group's runs (seed0 first)

    @property
    def model(self) -> str:
        """"mmg", "nn" or "hybrid"."""
        return str(self.summary.get("model", "mmg")).lower()

    @property
    def dataset(self) -> str:
        value = self.summary.get("dataset")
        return str(value) if value not in (None, "") else "-"

    @property
    def gate_threshold(self) -> float | None:
        """kNN threshold of the OOD gate (summary.json "gate", else knn.pt), or None; a
        knn.pt that breaks its contract is a `CheckpointError` (`read_knn_bank`)."""
        gate = self.summary.get("gate") or {}
        value = gate.get("threshold") if isinstance(gate, dict) else None
        if value is None and (self.path / "knn.pt").is_file():  # checked like any load of it
            value = float(read_knn_bank(self.path / "knn.pt", load_experiment(self.path / "config.toml"))["threshold"])
        try:
            value = float(value) if value is not None else None
        except (TypeError, ValueError):
            return None
        return value if value is not None and math.isfinite(value) else None

    def scenarios(self) -> list[str]:
        """Scenario names in the order of metrics.csv."""
        return list(dict.fromkeys(self.metrics["scenario"].astype(str)))

    def horizons(self) -> list[int]:
        return sorted({int(round(h)) for h in self.metrics["horizon_s"]})

    def trace(self, scenario: str, horizon_s: float) -> pd.DataFrame | None:
        """The trace of the scenario's (first) file at a horizon, or None when absent."""
        key = (scenario, int(round(horizon_s)))
        if key not in self._traces:
            rows = self.metrics[(self.metrics["scenario"].astype(str) == scenario)
                                & ((self.metrics["horizon_s"] - horizon_s).abs() < 0.5)]
            frame = None
            if len(rows):
                stem = Path(str(rows.iloc[0]["file"])).stem
                path = self.path / "traces" / trace_name(stem, horizon_s)
                frame = _read_table(path, TRACE_COLUMNS, required=False)
            self._traces[key] = frame
        return self._traces[key]


@dataclass
class SweepRecord:
    """A sweep directory (`sysid.sweep.study`): trials (results.csv), configurations over
    their seeds (points.csv, best first), the varied keys and the chosen configuration's runs."""

    trials: pd.DataFrame
    points: pd.DataFrame
    keys: list[str]
    chosen: list[RunRecord]


@dataclass
class ReportSource:
    """What a report is built from: one run, or a reproduction's runs and summary."""

    path: Path
    kind: str  # "run", "reproduction", "sweep" or "preprocessing"
    runs: list[RunRecord]
    summary: dict
    quality: list[QualityReport] = field(default_factory=list)  # preprocessing *.report.json
    sweep: SweepRecord | None = None

    @property
    def title(self) -> str:
        return self.path.resolve().name

    @property
    def missing_runs(self) -> list[str]:
        """Protocol runs a reproduction left out (``sysid reproduce --only``): a partial one."""
        if self.kind != "reproduction":
            return []
        done = set(self.summary.get("runs") or [r.name for r in self.runs])
        return [name for name in self.summary.get("protocol") or [] if name not in done]


def _run_order(run: RunRecord) -> tuple:
    """MMG (paper X'vr first), NN, hybrid; data sets in order."""
    return (list(ModelKind).index(ModelKind(run.model)), run.name != "mmg_paper", run.dataset, run.name)


def read_run_dir(path: Path) -> RunRecord:
    """A run directory (`sysid.runs.rundir`), checked."""
    path = Path(path)
    verify_run_dir(path)
    summary = read_json(path / "summary.json")
    config_path = path / "config.toml"
    config_text, config = "", {}
    if config_path.is_file():
        config_text = config_path.read_text()
        try:
            config = tomllib.loads(config_text)
        except tomllib.TOMLDecodeError as exc:
            raise CheckpointError(f"{config_path}: not valid TOML ({exc})") from None
    metrics = _read_table(path / "metrics.csv", METRICS_COLUMNS)
    # a file outside the protocol's scenarios (held-out) is named by its file stem
    stems = metrics["file"].astype(str).map(lambda f: Path(f).stem)
    scenario = metrics["scenario"].where(metrics["scenario"].notna(), "").astype(str).str.strip()
    metrics["scenario"] = scenario.where(scenario != "", stems)
    history = _read_table(path / "history.csv", ["epoch", "train_loss", "val_loss"], required=False)
    model = str(summary.get("model", "mmg")).lower()
    if model not in ModelKind.offered():
        raise CheckpointError(f"{path / 'summary.json'}: model {model!r} is not one of {ModelKind.listing()}")
    return RunRecord(path.name, path, summary, config_text, config,
                     metrics, history)


def read_seed_group(path: Path) -> RunRecord:
    """``runs/{name}/seed{k}/`` of ``sysid reproduce --seeds N``: one record whose metrics are
    the seed means with their spread (`sysid.protocol.seeds.seed_metrics`); summary, history and
    traces are those of its first seed."""
    seed_dirs = sorted((p for p in path.iterdir() if p.is_dir() and p.name.startswith("seed")),
                       key=lambda p: (len(p.name), p.name))
    if not seed_dirs:
        raise CheckpointError(f"{path}: neither a run directory nor a folder of seed runs (seed0/, seed1/, ...)")
    records = [read_run_dir(p) for p in seed_dirs]
    first = records[0]
    metrics = seed_metrics([r.metrics for r in records])
    summary = {**first.summary, "seeds": [r.summary.get("seed") for r in records]}
    return RunRecord(path.name, first.path, summary, first.config_text, first.config, metrics, first.history,
                     seeds=records)


def read_quality_reports(*folders: Path) -> list[QualityReport]:
    """Every ``*.report.json`` directly in the folders, sorted by file name."""
    reports = []
    for folder in folders:
        for path in sorted(Path(folder).glob("*.report.json")) if Path(folder).is_dir() else []:
            data = read_json(path)
            data.setdefault("file", path.name.removesuffix(".report.json"))
            try:
                reports.append(QualityReport.from_dict(data))
            except (TypeError, ValueError) as exc:
                raise CheckpointError(f"{path}: not a preprocessing quality report ({exc})") from None
    return reports


def read_source(path) -> ReportSource:
    """A run directory (has summary.json and metrics.csv) or a reproduction directory (has runs/)."""
    path = Path(path)
    if not path.is_dir():
        raise CheckpointError(f"{path}: no such directory")
    if (path / "runs").is_dir():
        verify_manifest(path, "reproduction")
    elif has_manifest(path):  # a run or preprocessing output; older ones have no manifest
        verify_manifest(path)
    quality = read_quality_reports(path, path / "preprocessing")
    if (path / "runs").is_dir():
        run_dirs = sorted(p for p in (path / "runs").iterdir() if p.is_dir())
        if not run_dirs:
            raise CheckpointError(f"{path / 'runs'}: holds no run directories")
        summary = read_json(path / "summary.json") if (path / "summary.json").exists() else {}
        runs = sorted((read_run_dir(p) if (p / "manifest.json").is_file() or (p / "summary.json").is_file()
                       else read_seed_group(p) for p in run_dirs), key=_run_order)
        return ReportSource(path, "reproduction", runs, summary, quality)
    if (path / "sweep.toml").is_file() and (path / "results.csv").is_file():
        return read_sweep(path, quality)
    if (path / "summary.json").exists() or (path / "metrics.csv").exists():
        run = read_run_dir(path)
        return ReportSource(path, "run", [run], run.summary, quality)
    if quality:
        return ReportSource(path, "preprocessing", [], {}, quality)
    raise CheckpointError(f"{path}: neither a run directory (summary.json, metrics.csv), "
                          "a reproduction directory (runs/), a sweep directory (sweep.toml, results.csv) nor "
                          "preprocessing output (*.report.json)")


def read_sweep(path: Path, quality: list[QualityReport]) -> ReportSource:
    """A sweep directory: its tables, summary and the chosen configuration's seed runs (the
    report's run figures and table show the chosen configuration's first seed)."""
    summary = read_json(path / "summary.json")
    trials = _read_table(path / "results.csv", ["point", "seed", "run", "status", "val_loss"])
    points = _read_table(path / "points.csv", ["point", "val_loss_mean"])
    keys = list(summary.get("keys") or [])
    best = summary.get("best") or {}
    chosen = [read_run_dir(path / run) for run in best.get("runs", [])]
    return ReportSource(path, "sweep", chosen[:1], summary, quality, SweepRecord(trials, points, keys, chosen))
