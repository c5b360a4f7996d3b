"""Reading a run directory or a reproduction directory (layout: `sysid.runs.layout`).

Runs are read through `sysid.runs.rundir.RunDir`: every file the report needs is checked
when it is read; a missing or corrupt file raises `CheckpointError` naming it, and a run or
reproduction whose manifest is missing or disagrees with its files is refused
(`IncompleteOutputError`). Traces are read lazily (a full reproduction holds ~70 of them).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from preprocessing.quality import QualityReport
from sysid.errors import CheckpointError
from sysid.config.choices import ModelKind, TestLogs
from sysid.data.splits import PAPER_TEST_STEMS
from sysid.evaluation.verdict import BaselineVerdict, seed_mean_verdict
from sysid.store.manifest import has_manifest, seed_folder, seed_order, verify_manifest
from sysid.store.target import OutputKind, record_file
from sysid.runs.rundir import RunDir, read_table
from sysid.records.base import read_json_object
from sysid.runs.reproduction import Reproduction
from sysid.records.summary import RunSummary
from sysid.sweep.summary import SweepSummary
from sysid.protocol.seeds import seed_metrics


@dataclass
class RunRecord:
    """One run directory: its summary, config, metrics, loss history and traces.

    metrics : METRICS_COLUMNS, RMSE in m/s (u, v_m) and rad/s (r); history : epoch-wise
    losses or None (MMG-only runs).
    """

    name: str   # the run directory's name (mmg_paper, hybrid_D2, ... in a reproduction)
    path: Path
    summary: RunSummary
    config_text: str
    config: dict
    metrics: pd.DataFrame
    history: pd.DataFrame | None
    _traces: dict = field(default_factory=dict, repr=False)
    seeds: list["RunRecord"] = field(default_factory=list)   # a seed group's runs (seed0 first)
    baseline_metrics: pd.DataFrame | None = None  # the physics baselines on the test logs (BASELINE_METRICS_COLUMNS)

    @property
    def verdict(self) -> BaselineVerdict | None:
        """The run against its physics baselines (`RunSummary.verdict`), or None."""
        if self.summary.verdict is None:
            return None
        try:
            return BaselineVerdict.from_dict(self.summary.verdict.to_json())
        except (KeyError, TypeError, ValueError) as exc:
            raise CheckpointError(f"{self.run_dir.summary}: malformed verdict ({exc})") from None

    @property
    def model_verdict(self) -> BaselineVerdict | None:
        """The model against its physics baselines: a seed group's seeds as members of one model
        (`seed_mean_verdict`, docs: How sysid judges a model), else the run's own verdict; None
        when a run or any seed has none."""
        if not self.seeds:
            return self.verdict
        verdicts = [r.verdict for r in self.seeds]
        return seed_mean_verdict([v for v in verdicts if v is not None]) if all(verdicts) else None

    @property
    def paper_protocol(self) -> bool:
        """Trained on D1/D2 (or not trained) and tested on the paper's six test files."""
        data = self.summary.data
        if data is not None:
            return data.test_set is TestLogs.PAPER and data.training in ("D1", "D2", "-")
        stems = {Path(str(f)).stem for f in self.metrics["file"]}
        return self.dataset in ("D1", "D2") or (self.dataset == "-" and stems == set(PAPER_TEST_STEMS))

    @property
    def run_dir(self) -> RunDir:
        return RunDir(self.path)

    @property
    def model(self) -> ModelKind:
        """The run's model (written "mmg", "nn" or "hybrid"; checked by `read_run_dir`)."""
        return ModelKind(self.summary.model.lower())

    @property
    def dataset(self) -> str:
        return self.summary.dataset or "-"

    @property
    def gate_threshold(self) -> float | None:
        """kNN threshold of the OOD gate (summary.json "gate", else knn.pt), or None."""
        value = self.summary.gate.threshold
        if value is None and self.run_dir.knn.is_file():
            try:
                value = float(self.run_dir.read_knn_bank().threshold)
            except CheckpointError:  # an unreadable bank only costs the threshold line
                return None
        return float(value) if value is not None and math.isfinite(value) else None

    def scenarios(self) -> list[str]:
        """Scenario names in the order of metrics.csv."""
        return list(dict.fromkeys(self.metrics["scenario"].astype(str)))

    def horizons(self) -> list[int]:
        return sorted({int(round(h)) for h in self.metrics["horizon_s"]})

    @property
    def baselines(self) -> list[str]:
        """The labels of the physics baselines scored beside the run (baseline_metrics.csv), in
        its order; [] for a run without them."""
        if self.baseline_metrics is None:
            return []
        return list(dict.fromkeys(self.baseline_metrics["baseline"].astype(str)))

    def trace(self, scenario: str, horizon_s: float, baseline: str | None = None) -> pd.DataFrame | None:
        """The trace of the scenario's (first) file at a horizon, or None when absent;
        `baseline`: that physics baseline's trace on the same windows (`baselines`)."""
        key = (scenario, int(round(horizon_s)), baseline)
        if key not in self._traces:
            rows = self.metrics[(self.metrics["scenario"].astype(str) == scenario)
                                & ((self.metrics["horizon_s"] - horizon_s).abs() < 0.5)]
            frame = None
            if len(rows):
                stem = Path(str(rows.iloc[0]["file"])).stem
                frame = (self.run_dir.read_trace(stem, horizon_s) if baseline is None
                         else self.run_dir.read_baseline_trace(baseline, stem, horizon_s))
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
    summary: SweepSummary
    path: Path | None = None   # the sweep directory


@dataclass
class ReportSource:
    """What a report is built from: one run, a reproduction's runs and summary, a sweep or
    preprocessing output."""

    path: Path
    kind: str  # "run", "reproduction", "sweep" or "preprocessing"
    runs: list[RunRecord]
    quality: list[QualityReport] = field(default_factory=list)  # preprocessing *.report.json
    sweep: SweepRecord | None = None
    reproduction: Reproduction | None = None  # a reproduction's summary.json (None: it has none)
    maneuver_indices: pd.DataFrame | None = None  # a reproduction's maneuver_indices.csv (recorded vs predicted)
    linked_sweeps: list[SweepRecord] = field(default_factory=list)  # sweeps the report shows beside (``--sweep``)

    @property
    def title(self) -> str:
        return self.path.resolve().name

    @property
    def paper_protocol(self) -> bool:
        """A reproduction, or runs of the paper's protocol: only then the paper's values and
        figure numbers appear in the report."""
        return self.kind == "reproduction" or (bool(self.runs) and all(r.paper_protocol for r in self.runs))

    @property
    def verdict(self) -> BaselineVerdict | None:
        """Page 1 of a run's or a sweep's report: the run's verdict, or the seed mean of the
        chosen configuration's; None for a reproduction or runs without one."""
        if self.kind == "sweep" and self.sweep is not None:
            verdicts = [r.verdict for r in self.sweep.chosen]
            return seed_mean_verdict(verdicts) if verdicts and all(verdicts) else None
        return self.runs[0].verdict if self.kind == "run" and self.runs else None

    @property
    def missing_runs(self) -> list[str]:
        """Protocol runs a reproduction left out (``sysid reproduce --only``): a partial one."""
        if self.reproduction is None:
            return []
        done = set(self.reproduction.runs or [r.name for r in self.runs])
        return [name for name in self.reproduction.protocol or () if name not in done]


def _run_order(run: RunRecord) -> tuple:
    """MMG (paper X'vr first), NN, hybrid; data sets in order."""
    return (list(ModelKind).index(run.model), run.name != "mmg_paper", run.dataset, run.name)


def read_run_dir(path: Path) -> RunRecord:
    """A run directory (`sysid.runs.layout`), checked."""
    run = RunDir.open(path)
    summary = run.read_summary()
    config_text, config = run.read_config_text(), run.read_config()
    metrics = run.read_metrics()
    # a file outside the protocol's scenarios (held-out) is named by its file stem
    stems = metrics["file"].astype(str).map(lambda f: Path(f).stem)
    scenario = metrics["scenario"].where(metrics["scenario"].notna(), "").astype(str).str.strip()
    metrics["scenario"] = scenario.where(scenario != "", stems)
    if summary.model.lower() not in ModelKind.offered():
        raise CheckpointError(f"{run.summary}: model {summary.model.lower()!r} is not one of {ModelKind.listing()}")
    return RunRecord(run.path.name, run.path, summary, config_text, config, metrics, run.read_history(),
                     baseline_metrics=run.read_baseline_metrics())


def read_seed_group(path: Path) -> RunRecord:
    """``runs/{name}/seed{k}/`` of ``sysid reproduce --seeds N``: one record whose metrics are
    the seed means with their spread (`sysid.protocol.seeds.seed_metrics`); summary, history and
    traces are those of its first seed."""
    seed_dirs = sorted((p for p in path.iterdir() if p.is_dir() and p.name.startswith("seed")),
                       key=lambda p: seed_order(p.name))
    if not seed_dirs:
        raise CheckpointError(f"{path}: neither a run directory nor a folder of seed runs (seed0/, seed1/, ...)")
    records = [read_run_dir(p) for p in seed_dirs]
    first = records[0]
    metrics = seed_metrics([r.metrics for r in records])
    return RunRecord(path.name, first.path, first.summary, first.config_text, first.config, metrics, first.history,
                     seeds=records)


def read_quality_reports(*folders: Path) -> list[QualityReport]:
    """Every ``*.report.json`` directly in the folders, sorted by file name."""
    reports = []
    for folder in folders:
        for path in sorted(Path(folder).glob("*.report.json")) if Path(folder).is_dir() else []:
            data = read_json_object(path)
            data.setdefault("file", path.name.removesuffix(".report.json"))
            try:
                reports.append(QualityReport.from_dict(data))
            except (TypeError, ValueError) as exc:
                raise CheckpointError(f"{path}: not a preprocessing quality report ({exc})") from None
    return reports


def read_source(path, sweeps=()) -> ReportSource:
    """A run directory (has summary.json and metrics.csv) or a reproduction directory (has
    runs/); `sweeps`: sweep directories whose validation landscape the report shows beside."""
    source = _read_source(Path(path))
    source.linked_sweeps = [read_linked_sweep(Path(s)) for s in sweeps]
    return source


def read_linked_sweep(path: Path) -> SweepRecord:
    """A sweep directory given beside a report's source, checked to be one."""
    if not ((path / "sweep.toml").is_file() and (path / "results.csv").is_file()):
        raise CheckpointError(f"{path}: not a sweep directory (sweep.toml and results.csv of `sysid sweep`); "
                              "give the directory `sysid sweep -o` wrote")
    sweep = read_sweep(path, []).sweep
    return sweep


def _read_source(path: Path) -> ReportSource:
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
        record = record_file(path, OutputKind.REPRODUCTION)
        reproduction = Reproduction.read(record) if record.exists() else None
        runs = sorted((read_run_dir(p) if RunDir(p).manifest.is_file() or RunDir(p).summary.is_file()
                       else read_seed_group(p) for p in run_dirs), key=_run_order)
        indices = read_table(path / "maneuver_indices.csv", ["scenario", "maneuver", "model"], required=False)
        return ReportSource(path, "reproduction", runs, quality, reproduction=reproduction, maneuver_indices=indices)
    if (path / "sweep.toml").is_file() and (path / "results.csv").is_file():
        return read_sweep(path, quality)
    if RunDir(path).summary.exists() or RunDir(path).metrics.exists():
        return ReportSource(path, "run", [read_run_dir(path)], quality)
    if quality:
        return ReportSource(path, "preprocessing", [], quality)
    if seed_folder(path):
        raise CheckpointError(str(seed_folder(path)))
    raise CheckpointError(f"{path}: neither a run directory (summary.json, metrics.csv), "
                          "a reproduction directory (runs/), a sweep directory (sweep.toml, results.csv) nor "
                          "preprocessing output (*.report.json)")


def read_sweep(path: Path, quality: list[QualityReport]) -> ReportSource:
    """A sweep directory: its tables, summary and the chosen configuration's seed runs (the
    report's run figures and table show the chosen configuration's first seed)."""
    summary = SweepSummary.read(record_file(path, OutputKind.SWEEP))
    trials = read_table(path / "results.csv", ["point", "seed", "run", "status", "val_loss_multistep"])
    points = read_table(path / "points.csv", ["point", "val_loss_multistep_mean"])
    keys = list(summary.keys)
    chosen = [read_run_dir(path / run) for run in (summary.best.runs if summary.best else ())]
    return ReportSource(path, "sweep", chosen[:1], quality, SweepRecord(trials, points, keys, chosen, summary, path))
