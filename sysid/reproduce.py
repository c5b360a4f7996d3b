"""The whole benchmark protocol in one call: MMG-only (paper's and lab's X'vr), NN-only and
hybrid on D1 and D2, evaluated on the six test files, tables beside the paper's 7 and 8."""
from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import Callable

import numpy as np
import pandas as pd

from sysid.data import read_run
from sysid.datasets import TEST_FILES, data_root, test_files, training_files
from sysid.errors import ConfigError
from sysid.experiment import Experiment, load_experiment
from sysid.files import write_csv, write_text
from sysid.paper import paper_table
from sysid.rundir import TABLE_COLUMNS
from sysid.runs import evaluate_model, write_run

CONFIGS = Path(__file__).resolve().parents[1] / "configs"
# run name -> (config file, model label in the tables, data set label)
PROTOCOL = {
    "mmg_paper": ("mmg_paper.toml", "MMG", "D1+D2"),
    "mmg_lab": ("mmg_lab.toml", "MMG (lab X'vr)", "D1+D2"),
    "nn_D1": ("nn_D1.toml", "NN", "D1"),
    "nn_D2": ("nn_D2.toml", "NN", "D2"),
    "hybrid_D1": ("hybrid_D1.toml", "Hybrid", "D1"),
    "hybrid_D2": ("hybrid_D2.toml", "Hybrid", "D2"),
    # beyond the paper: hull coefficients identified by gradient, alone and under the FNN
    "mmg_identified_D2": ("mmg_identified_D2.toml", "MMG (identified)", "D2"),
    "hybrid_identified_D2": ("hybrid_identified_D2.toml", "Hybrid (identified MMG)", "D2"),
}
MODEL_ORDER = ["MMG", "MMG (lab X'vr)", "MMG (identified)", "NN", "Hybrid", "Hybrid (identified MMG)"]
SCENARIO_ORDER = list(TEST_FILES)
_PAPER_NAMES = {"Turning 20": "Turning 20", "Turning 35": "Turning 35"}


def comparison_table(results: dict[str, tuple[str, str, pd.DataFrame]]) -> pd.DataFrame:
    """Ours beside the paper's, one row per scenario, model, data set and horizon."""
    paper = paper_table().set_index(["scenario", "model", "dataset", "horizon_s"])
    rows = []
    for _, (label, dataset, metrics) in results.items():
        for _, m in metrics.iterrows():
            for ds in (("D1", "D2") if dataset == "D1+D2" else (dataset,)):
                key = (m.scenario, label, ds, int(m.horizon_s))
                ref = paper.loc[key] if key in paper.index else None
                rows.append({"scenario": m.scenario, "model": label, "dataset": ds,
                             "horizon_s": int(m.horizon_s), "rmse_u": m.rmse_u, "rmse_v": m.rmse_v,
                             "rmse_r": m.rmse_r,
                             "paper_u": ref.rmse_u if ref is not None and label in ("MMG", "NN", "Hybrid") else np.nan,
                             "paper_v": ref.rmse_v if ref is not None and label in ("MMG", "NN", "Hybrid") else np.nan,
                             "paper_r": ref.rmse_r if ref is not None and label in ("MMG", "NN", "Hybrid") else np.nan})
    table = pd.DataFrame(rows, columns=TABLE_COLUMNS)
    order = {s: i for i, s in enumerate(SCENARIO_ORDER)}
    models = {m: i for i, m in enumerate(MODEL_ORDER)}
    table["_o"] = table.scenario.map(order) * 100 + table.model.map(models) * 10 + (table.dataset == "D2")
    return table.sort_values(["horizon_s", "_o"]).drop(columns="_o").reset_index(drop=True)


def markdown_table(table: pd.DataFrame, horizon: int) -> str:
    """The paper's layout: ours (paper) per cell, u v_m r for D1 and D2."""
    t = table[table.horizon_s == horizon]
    head = (f"RMSE [m/s, m/s, rad/s] of {horizon}-s predictions: ours (paper). Table "
            f"{7 if horizon == 30 else 8} of the paper.\n\n"
            "| test | model | D1 u | D1 v_m | D1 r | D2 u | D2 v_m | D2 r |\n|---|---|---|---|---|---|---|---|\n")
    lines = []
    for scenario in SCENARIO_ORDER:
        for model in MODEL_ORDER:
            if t[(t.scenario == scenario) & (t.model == model)].empty:
                continue
            cells = []
            for ds in ("D1", "D2"):
                row = t[(t.scenario == scenario) & (t.model == model) & (t.dataset == ds)]
                for c in ("u", "v", "r"):
                    if row.empty:
                        cells.append("–")
                        continue
                    ours, ref = row[f"rmse_{c}"].iloc[0], row[f"paper_{c}"].iloc[0]
                    cells.append(f"{ours:.4f}" + ("" if np.isnan(ref) else f" ({ref:.4f})"))
            lines.append(f"| {scenario} | {model} | " + " | ".join(cells) + " |")
    return head + "\n".join(lines) + "\n"


def scorecard(table: pd.DataFrame, baseline: str = "MMG") -> dict:
    """Hybrid against MMG-only with the same X'vr (`baseline` label) and against the paper's
    hybrid, cell by cell."""
    out: dict = {"baseline": baseline}
    for ds in ("D1", "D2"):
        hyb = table[(table.model == "Hybrid") & (table.dataset == ds)].set_index(["scenario", "horizon_s"])
        mmg = table[(table.model == baseline) & (table.dataset == ds)].set_index(["scenario", "horizon_s"])
        cols = ["rmse_u", "rmse_v", "rmse_r"]
        ratio = hyb[cols] / mmg.loc[hyb.index, cols]
        at30 = ratio.xs(30, level="horizon_s")
        paper_cols = ["paper_u", "paper_v", "paper_r"]
        beats = (hyb[cols].to_numpy() < hyb[paper_cols].to_numpy())
        out[ds] = {
            "reduction_vs_mmg_30s_by_scenario": {s: float(1 - at30.loc[s].mean()) for s in at30.index},
            "reduction_vs_mmg_30s_mean": float(1 - at30.to_numpy().mean()),
            "reduction_vs_mmg_100s_mean": float(1 - ratio.xs(100, level="horizon_s").to_numpy().mean()),
            "cells_beating_paper_hybrid": int(beats.sum()), "cells": int(beats.size),
        }
    return out


def reproduce(out_dir: str | os.PathLike, data: str | os.PathLike | None = None,
              only: list[str] | None = None, progress: bool = True,
              overrides: dict | None = None, log: Callable[[str], None] = print) -> dict:
    """Run the protocol; write runs/, comparison.csv, table7.md, table8.md, summary.json."""
    from sysid.train import Trainer
    started = time.perf_counter()
    out = Path(out_dir)
    data_root(data)  # clear error before any work when the data is missing
    tests = [read_run(p) for p in test_files(data).values()]
    cache: dict[str, list] = {}
    results: dict[str, tuple[str, str, pd.DataFrame]] = {}
    shares: dict[str, dict] = {}
    names = only or list(PROTOCOL)
    for i, name in enumerate(names, 1):
        if name not in PROTOCOL:
            raise ConfigError(f"unknown protocol run {name!r}: choose from {', '.join(PROTOCOL)}")
        config, label, dataset = PROTOCOL[name]
        exp: Experiment = load_experiment(CONFIGS / "experiments" / config)
        if overrides:
            exp = exp.replace(**overrides) if exp.experiment.model != "mmg" else exp
        t0 = time.perf_counter()
        log(f"[{i}/{len(names)}] {name}: {label} on {dataset}")
        history, info = None, {}
        if exp.experiment.model == "mmg" and not exp.identify.parameters:
            from sysid.runs import build_model
            model = build_model(exp)
        else:
            ds = exp.experiment.dataset
            if ds not in cache:
                cache[ds] = [read_run(p) for p in training_files(ds, data)]
            trainer = Trainer(exp, progress=progress, log=lambda m: log("    " + m)).fit(cache[ds])
            model, history, info = trainer.model_.cpu().double(), trainer.history_, trainer.info_
        evaluation = evaluate_model(model, tests, exp.evaluation.horizons, exp.evaluation.integrator)
        write_run(out / "runs" / name, exp, model, evaluation, history, info, time.perf_counter() - t0)
        results[name] = (label, dataset, evaluation.metrics)
        shares[name] = evaluation.gate_off_share
        log(f"    done in {time.perf_counter() - t0:.0f} s")
    table = comparison_table(results)
    write_csv(table, out / "comparison.csv", float_format="%.5f")
    for horizon, fname in ((30, "table7.md"), (100, "table8.md")):
        write_text(markdown_table(table, horizon), out / fname)
    summary = {"seconds": time.perf_counter() - started, "runs": names}
    if {"hybrid_D1", "hybrid_D2", "mmg_paper", "mmg_lab"} <= set(names):
        hybrid_xvr = load_experiment(CONFIGS / "experiments" / PROTOCOL["hybrid_D2"][0]).mmg.overrides
        paper_xvr = any(abs(float(v) - 0.4535) < 1e-9 for v in hybrid_xvr.values())
        summary["scorecard"] = scorecard(table, "MMG" if paper_xvr else "MMG (lab X'vr)")
    if "hybrid_identified_D2" in names:
        hyb = table[(table.model == "Hybrid (identified MMG)")]
        ref = table[(table.model == "Hybrid") & (table.dataset == "D2")].set_index(["scenario", "horizon_s"])
        ours = hyb.set_index(["scenario", "horizon_s"])[["rmse_u", "rmse_v", "rmse_r"]]
        paper = ref.loc[ours.index, ["paper_u", "paper_v", "paper_r"]].to_numpy()
        summary["identified_hybrid_D2_cells_beating_paper_hybrid"] = [int((ours.to_numpy() < paper).sum()),
                                                                      int(paper.size)]
    random_file = Path(TEST_FILES["Random"]).stem
    summary["gate_off_share_random_30s"] = {
        n: shares[n].get(f"{random_file}_h30.csv") for n in names if n.startswith("hybrid")}
    write_text(json.dumps(summary, indent=2), out / "summary.json")
    return summary
