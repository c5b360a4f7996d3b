"""Every Table 7/8 cell of a reproduction relative to MMG-only: the hybrid and NN-only (seed
means with their min-max over the seeds) and the paper's printed hybrid, each divided by the
RMSE of the MMG the hybrid corrects (the baseline every cut is measured against).

A cell is one scenario, horizon [s] and channel (u, v_m [m/s]; r [rad/s]); a ratio below 1 is
a smaller error than the baseline MMG's. The ratios are dimensionless, so the 36 cells of a
data set share one (log) axis.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from sysid.config.choices import ModelKind
from sysid.protocol.paper import SCENARIO_ORDER, paper_rmse, run_label, run_variant, scenario_key
from sysid.report.palette import model_colour
from sysid.report.source import ReportSource, RunRecord

CHANNELS = ("u", "v", "r")                            # metrics' rmse_{channel}
CHANNEL_NAMES = {"u": "u", "v": "v_m", "r": "r"}
CELL_COLUMNS = ["model", "scenario", "horizon_s", "channel", "ratio", "low", "high", "n_seeds"]


@dataclass(frozen=True)
class ModelSeeds:
    """A learned model's RMSE per seed: columns seed, scenario, horizon_s, rmse_u, rmse_v, rmse_r."""

    label: str
    colour: str
    per_seed: pd.DataFrame


@dataclass(frozen=True)
class CellRatios:
    """One data set's cells: `cells` (CELL_COLUMNS: per model the seed mean's ratio to the
    baseline and the min (`low`) and max (`high`) of the seeds' ratios), `paper` (scenario,
    horizon_s, channel, ratio: the paper's printed hybrid over our baseline), in the order
    `scenarios`, `horizons`."""

    dataset: str
    baseline: str
    baseline_colour: str
    models: tuple[ModelSeeds, ...]
    cells: pd.DataFrame
    paper: pd.DataFrame
    scenarios: tuple[str, ...]
    horizons: tuple[int, ...]

    @property
    def seeds(self) -> int:
        """The most seeds of any model (1: a single-seed reproduction, no spread)."""
        return int(self.cells["n_seeds"].max()) if len(self.cells) else 0

    def beating(self, model: str, other: str) -> tuple[int, int]:
        """(cells where `model`'s seed mean is below `other`'s, cells both have)."""
        a = self.cells[self.cells.model == model].set_index(["scenario", "horizon_s", "channel"]).ratio
        b = self.cells[self.cells.model == other].set_index(["scenario", "horizon_s", "channel"]).ratio
        shared = a.index.intersection(b.index)
        return int((a.loc[shared] < b.loc[shared]).sum()), len(shared)


def seed_rmse(run: RunRecord) -> pd.DataFrame:
    """A run's RMSE per seed (a single run: its one seed), scenario and horizon [s]."""
    frames = []
    for record in run.seeds or [run]:
        m = record.metrics
        frames.append(pd.DataFrame({"seed": record.summary.seed if record.summary.seed is not None else 0,
                                    "scenario": m["scenario"].astype(str), "horizon_s": m["horizon_s"].round().astype(int),
                                    **{f"rmse_{c}": m[f"rmse_{c}"].astype(float) for c in CHANNELS}}))
    return pd.concat(frames, ignore_index=True)


def relative_cells(models: list[ModelSeeds], baseline: pd.DataFrame) -> pd.DataFrame:
    """CELL_COLUMNS for every model: seed mean / baseline, and the seeds' min and max of
    RMSE / baseline. `baseline`: scenario, horizon_s, rmse_u, rmse_v, rmse_r (one row per cell)."""
    base = baseline.groupby(["scenario", "horizon_s"])[[f"rmse_{c}" for c in CHANNELS]].first()
    rows = []
    for model in models:
        groups = model.per_seed.groupby(["scenario", "horizon_s"], sort=False)
        for (scenario, horizon), seeds in groups:
            if (scenario, horizon) not in base.index:
                continue
            for c in CHANNELS:
                ref = float(base.loc[(scenario, horizon), f"rmse_{c}"])
                values = seeds[f"rmse_{c}"].to_numpy() / ref
                rows.append([model.label, scenario, int(horizon), c, float(seeds[f"rmse_{c}"].mean()) / ref,
                             float(values.min()), float(values.max()), len(values)])
    return pd.DataFrame(rows, columns=CELL_COLUMNS)


def paper_ratios(baseline: pd.DataFrame, dataset: str) -> pd.DataFrame:
    """The paper's printed hybrid (Tables 7/8) over our baseline's RMSE, per cell it prints."""
    rows = []
    for r in baseline.itertuples(index=False):
        ref = paper_rmse(str(r.scenario), "hybrid", dataset, r.horizon_s)
        for i, c in enumerate(CHANNELS):
            if ref is not None:
                rows.append([str(r.scenario), int(round(r.horizon_s)), c, ref[i] / float(getattr(r, f"rmse_{c}"))])
    return pd.DataFrame(rows, columns=["scenario", "horizon_s", "channel", "ratio"])


def baseline_run(runs: list[RunRecord]) -> RunRecord | None:
    """The MMG-only run whose MMG the hybrids correct (the same coefficient overrides as the
    first hybrid's; the lab's X'vr in the protocol), else the first MMG-only run."""
    mmg = [r for r in runs if r.model == ModelKind.MMG and run_variant(r.name, r.dataset).startswith("mmg")
           and not r.summary.identified]
    hybrid = next((r for r in runs if r.model == ModelKind.HYBRID), None)
    same = [r for r in mmg if hybrid is not None and dict(r.summary.mmg_overrides) == dict(hybrid.summary.mmg_overrides)]
    return (same or mmg or [None])[0]


def _paper_order(scenarios) -> list[str]:
    """The paper's scenario order (any spelling), then the others as found."""
    rank = {scenario_key(s): i for i, s in enumerate(SCENARIO_ORDER)}
    return sorted(dict.fromkeys(scenarios), key=lambda s: rank.get(scenario_key(s), len(rank)))


def dataset_cells(source: ReportSource) -> list[CellRatios]:
    """Per training data set (D1, D2) with NN-only or a hybrid: its cells against the baseline
    MMG run (`baseline_run`); none when the source has no such MMG run."""
    base_run = baseline_run(source.runs)
    if base_run is None:
        return []
    base_label = run_label(base_run.name, base_run.model, base_run.dataset)
    labels = {Path(str(f)).stem: s for f, s in zip(base_run.metrics["file"], base_run.metrics["scenario"])}
    baseline = seed_rmse(base_run)
    out = []
    for dataset in ("D1", "D2"):
        chosen = [r for r in source.runs if r.dataset == dataset and run_variant(r.name, r.dataset) in ("nn", "hybrid")]
        if not chosen:
            continue
        models = [ModelSeeds(run_label(r.name, r.model, r.dataset), model_colour(r.name, r.model, r.dataset), seed_rmse(r))
                  for r in sorted(chosen, key=lambda r: r.model != ModelKind.NN)]
        cells = relative_cells(models, baseline)
        scenarios = tuple(_paper_order(s for s in labels.values() if s in set(cells.scenario)))
        horizons = tuple(sorted(set(cells.horizon_s)))
        out.append(CellRatios(dataset, base_label, model_colour(base_run.name, base_run.model, base_run.dataset),
                              tuple(models), cells, paper_ratios(baseline, dataset), scenarios, horizons))
    return out
